"""Where the camera was: GNSS fixes from the files a camera or robot leaves, and the local
metric frame that a reconstruction is made in.

- :mod:`lburst.geo.fixes`: a fix (latitude, longitude, altitude, time), checked; a track of
  fixes with the jumps a platform cannot fly dropped, and positions at frame times.
- :mod:`lburst.geo.frame`: :class:`~lburst.geo.frame.GeoOrigin`, the east-north-up frame
  around a fix, with the UTM zone it lies in (pyproj).
- :mod:`lburst.geo.exif`: GPS in the EXIF of JPEG, TIFF and DNG frames (piexif); also written.
- :mod:`lburst.geo.srt`: the per-frame ``.SRT`` subtitles a DJI drone writes beside a video.
- :mod:`lburst.geo.outputs`: a model in that frame as a LAS point cloud with its CRS (laspy)
  and its cameras as GeoJSON.

ROS bags (``sensor_msgs/NavSatFix``) are read with their images, :mod:`lburst.burst.rosbag`.
Everything here needs the ``geo`` extra (``pip install 'lburst[geo]'``: pyproj, piexif, laspy,
rosbags); importing this package costs nothing.
"""
