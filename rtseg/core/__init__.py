"""The data every other part works on: a frame of a live source, a take (a recorded motion),
quaternion maths (scalar-last ``x, y, z, w``), the ring buffer of live frames, skeleton and
suit profiles, rig recognition, resampling, pose features, and the cut / status events a
session emits; and two helpers of logging: ``ratelog`` (recurring problems at a bounded
rate) and ``session_log`` (which session a record concerns).

May import ``rtseg.config`` (the shipped defaults) and nothing else of rtseg."""
