"""The data every other part works on: a frame of a live source, a take (a recorded motion),
quaternion maths (scalar-last ``x, y, z, w``), the ring buffer of live frames, skeleton and
suit profiles, rig recognition, resampling, pose features, and the cut / status events a
session emits.

Imports nothing of rtseg outside ``rtseg.core`` except ``rtseg.config`` (the shipped
defaults) and the file readers of ``rtseg.drivers.readers`` where a take is loaded."""
