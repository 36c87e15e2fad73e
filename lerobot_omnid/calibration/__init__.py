"""Camera calibration: the schema shared by datasets, configs and checkpoints, rig files, and the
``omnid-calibrate`` and ``omnid-attach-calibration`` commands."""
