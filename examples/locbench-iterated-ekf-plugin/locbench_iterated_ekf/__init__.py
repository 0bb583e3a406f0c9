"""An example locbench filter plugin: :class:`locbench_iterated_ekf.iterated_ekf.IteratedLandmarkEKF`, filter id
``iterated_ekf``."""
