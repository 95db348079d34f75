"""Benchmarks of ``cone-perception bench``: frames to time on (:mod:`.frames`), timing runs of the pipeline,
the adapter and the tracker (:mod:`.pipeline`), the runtime table of the thesis redone (:mod:`.table`).
Stage timers and summaries: :mod:`cone_perception.timing`; the forward pass alone: :mod:`cone_perception.bench.forward`."""
