"""Evaluation pipelines: loops over datasets, maps and simulated runs that measure toploc
(homing on images, localization, kidnapping, the thesis simulation)."""
