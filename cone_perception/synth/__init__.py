"""Synthetic data of ``cone-perception synth``: rendered frames with exact ground truth.

* :mod:`.config`: :class:`~.config.SynthConfig`, the camera, mount and scene switches, and its exact calibration;
* :mod:`.track`, :mod:`.scene`, :mod:`.motion`: tracks, car poses, a drive with its IMU;
* :mod:`.render`: cones and ground drawn into a camera frame;
* :mod:`.writers`: datasets, rosbags, contact sheets;
* :mod:`.mapcheck`: the localisation error left with a perfect detector.
"""
