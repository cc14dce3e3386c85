"""The burst layer: reading bursts and recordings, before any feature method sees them.

- :mod:`~lburst.burst.io`: image files and bursts in, results out (atomic writes).
- :mod:`~lburst.burst.frames`: a burst's checks, dtype scale and grayscale.
- :mod:`~lburst.burst.align`: translational alignment to the common frame.
- :mod:`~lburst.burst.motion`: in-burst motion (how frame ``k`` sees the common frame).
- :mod:`~lburst.burst.raw`: DNG and 16-bit linear frames.
- :mod:`~lburst.burst.keyframes`: keyframes where the view has moved far enough.
- :mod:`~lburst.burst.sources`: recordings (video, frame folders, DNG) cut into keyframe bursts.
"""
