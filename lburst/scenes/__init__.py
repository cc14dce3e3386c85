"""Burst scenes for reconstruction, folders of bursts with ``reference.json`` cameras
(:mod:`lburst.sfm.reference`): the synthetic night flight with exact ground truth
(:mod:`lburst.scenes.night_flight`, rendered by :mod:`~lburst.scenes.raycast` over the
toy city of :mod:`~lburst.scenes.city`) and scenes made from multi-view photos
(:mod:`lburst.scenes.photo_scene`)."""
