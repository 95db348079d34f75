"""Sub-commands of ``cone-perception`` (see :mod:`cone_perception.cli`)."""
