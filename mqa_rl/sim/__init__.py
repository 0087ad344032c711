"""Geometry shared by the data layer and the environment: the bin, the camera, silhouettes, and
the SAPIEN scene builder (the only module here that imports SAPIEN)."""
