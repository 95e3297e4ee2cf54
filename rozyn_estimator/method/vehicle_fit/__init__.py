"""The likelihood fit of the whole vehicle, either car, ROS-free: the vehicle's spectral model
(:mod:`.spectrum`), its Whittle fit (:mod:`.refine`), the road's intermittency and a varying
drive's stretches, the model check, calibration and budget (:mod:`.uncertainty`). The package
imports nothing itself: its modules are imported by name."""
