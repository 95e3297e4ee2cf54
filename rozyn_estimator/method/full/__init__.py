"""The one likelihood refinement and the full car's Rozyn stage, ROS-free: the vehicle's spectral
model (:mod:`.spectrum`, either car), its Whittle fit (:mod:`.refine`), calibration and budget
(:mod:`.uncertainty`); the full car's modal fit (:mod:`.fit`) and its window's update
(:func:`.stage.estimate_full`). The package imports nothing itself: its modules are imported by
name (the half car's pipeline imports the refinement without the full car's stage)."""
