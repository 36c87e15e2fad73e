"""Diagnostics of trained checkpoints: open-loop action error on expert episodes, what a representation knows
(linear probes of position, table shift), whether a policy uses its images."""
