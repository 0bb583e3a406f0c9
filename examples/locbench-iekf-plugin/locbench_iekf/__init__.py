"""An example locbench filter plugin: :class:`locbench_iekf.iekf.IteratedLandmarkEKF` (filter id ``iekf``)."""
