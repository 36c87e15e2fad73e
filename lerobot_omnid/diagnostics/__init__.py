"""Diagnostics: open-loop action error on expert episodes, what a representation knows (linear probes of
position, table shift), whether a policy uses its images, whether its head can command a layout's targets,
which layouts it solves, where a calibration error moves the object; their shared outputs (``summary``)."""
