"""GNSS from a camera's own files: EXIF GPS of JPEG, TIFF and DNG frames and DJI subtitles,
written and read back, with the bad inputs a drone leaves (frames without GPS, a fix outside
the Earth, subtitles without a fix)."""

import numpy as np
import pytest

pytest.importorskip("piexif")

from lburst.geo.exif import frames_track, gps_exif, read_gps, write_gps_jpeg  # noqa: E402
from lburst.geo.fixes import GnssError  # noqa: E402
from lburst.geo.srt import parse_subtitle, read_srt, srt_path, write_srt  # noqa: E402

FRAME = np.full((16, 24, 3), 90, np.uint8)


@pytest.mark.parametrize("lat, lon, alt", [(47.3769123, 8.5417456, 408.123), (-33.8688197, -151.2092955, -12.5)])
def test_a_jpeg_keeps_its_position_to_the_millimetre(tmp_path, lat, lon, alt):
    path = write_gps_jpeg(tmp_path / "f.jpg", FRAME, lat, lon, alt)
    got = read_gps(path)
    assert abs(got[0] - lat) * 111_000 < 0.005 and abs(got[1] - lon) * 111_000 < 0.005
    assert got[2] == pytest.approx(alt, abs=1e-3)


@pytest.mark.parametrize("suffix", [".tif", ".dng"])
def test_tiff_and_dng_frames_give_their_exif_position(tmp_path, suffix):
    from PIL import Image

    path = tmp_path / f"frame{suffix}"
    Image.fromarray(FRAME).save(path, format="TIFF", exif=gps_exif(10.5, -20.25, 3.0))
    assert read_gps(path) == pytest.approx((10.5, -20.25, 3.0))


def test_frames_without_gps_are_counted_and_named(tmp_path):
    frames = []
    for i in range(4):
        path = tmp_path / f"frame_{i}.jpg"
        if i == 1:
            from lburst.burst.io import write_image

            write_image(path, FRAME)
        else:
            write_gps_jpeg(path, FRAME, 47.0 + i * 1e-5, 8.0, 400.0)
        frames.append((path, i / 10, None))
    track = frames_track(frames, "night")
    assert [f.time for f in track.fixes] == [0.0, 0.2, 0.3]
    assert "3 of 4 frames" in track.source
    assert track.notes == ["night: 1 of 4 frames have no EXIF GPS (the first: frame_1.jpg)"]


def test_no_gps_at_all_is_no_track(tmp_path):
    from lburst.burst.io import write_image

    write_image(tmp_path / "a.jpg", FRAME)
    assert frames_track([(tmp_path / "a.jpg", 0.0, None)], "night") is None


def test_a_latitude_outside_the_earth_is_left_out_with_the_file_named(tmp_path):
    import piexif

    good = write_gps_jpeg(tmp_path / "good.jpg", FRAME, 47.0, 8.0, 400.0)
    bad = write_gps_jpeg(tmp_path / "bad.jpg", FRAME, 47.0, 8.0, 400.0)
    exif = piexif.load(str(bad))
    exif["GPS"][piexif.GPSIFD.GPSLatitude] = ((95, 1), (0, 1), (0, 1))
    piexif.insert(piexif.dump(exif), str(bad))
    track = frames_track([(good, 0.0, None), (bad, 0.1, None)], "night")
    assert len(track.fixes) == 1
    assert track.notes == [f"{bad}: latitude 95 is outside -90..90 degrees; not used"]


def test_a_malformed_gps_ifd_names_the_file(tmp_path):
    import piexif

    bad = write_gps_jpeg(tmp_path / "bad.jpg", FRAME, 47.0, 8.0, 400.0)
    exif = piexif.load(str(bad))
    exif["GPS"][piexif.GPSIFD.GPSLatitude] = ((47, 0), (0, 1), (0, 1))
    piexif.insert(piexif.dump(exif), str(bad))
    with pytest.raises(GnssError, match=f"^{bad}: EXIF GPSLatitude has a zero denominator"):
        read_gps(bad)


MAVIC = """1
00:00:00,000 --> 00:00:00,033
<font size="28">FrameCnt: 1, DiffTime: 33ms
2023-09-01 21:10:02.101
[iso: 3200] [shutter: 1/30.0] [fnum: 2.8] [ev: 0] [latitude: 22.543210] [longitude: 113.954320] [rel_alt: 1.200 abs_alt: 45.678] </font>

2
00:00:00,033 --> 00:00:00,066
<font size="28">FrameCnt: 2, DiffTime: 33ms
[iso: 3200] [latitude: 22.543220] [longitude: 113.954330] [rel_alt: 1.300 abs_alt: 45.778] </font>
"""

MAVIC_PRO = """1
00:00:01,000 --> 00:00:02,000
[latitude : -33.8600] [longtitude : 151.2000] [altitude: 120.50]
"""

PHANTOM = """1
00:00:00,000 --> 00:00:01,000
HOME(113.9431,22.5328) 2017.08.05 14:11:51
GPS(113.9432,22.5329,16) BAROMETER:64.8
ISO:100 Shutter:60 EV:0 Fnum:2.2

2
00:00:01,000 --> 00:00:02,000
F/3.5, SS 1000, ISO 100, EV 0, GPS (-122.3000, 47.6000, 19), D 24.64m, H 21.20m, H.S 0.00m/s
"""


def test_the_dji_subtitle_forms_give_time_latitude_longitude_and_altitude(tmp_path):
    (tmp_path / "a.SRT").write_text(MAVIC)
    track = read_srt(tmp_path / "a.SRT")
    assert [(f.time, f.lat, f.lon, f.alt) for f in track.fixes] == [
        (0.0, 22.54321, 113.95432, 45.678),
        (0.033, 22.54322, 113.95433, 45.778),
    ]
    assert parse_subtitle(MAVIC_PRO.split("\n", 2)[2]) == (-33.86, 151.2, 120.5)
    (tmp_path / "p.srt").write_text(PHANTOM)
    fixes = read_srt(tmp_path / "p.srt").fixes
    assert [(f.lat, f.lon, f.alt) for f in fixes] == [(22.5329, 113.9432, 64.8), (47.6, -122.3, 21.2)]


def test_the_subtitles_beside_a_video_are_found_by_its_stem(tmp_path):
    (tmp_path / "DJI_0001.MP4").write_bytes(b"")
    assert srt_path(tmp_path / "DJI_0001.MP4") is None
    (tmp_path / "DJI_0001.SRT").write_text(MAVIC)
    assert srt_path(tmp_path / "DJI_0001.MP4") == tmp_path / "DJI_0001.SRT"


def test_written_subtitles_read_back(tmp_path):
    fixes = [(47.0 + i * 1e-6, 8.0 - i * 1e-6, 400.0 + i / 100) for i in range(5)]
    write_srt(tmp_path / "v.SRT", [i / 20 for i in range(5)], fixes, 20.0)
    track = read_srt(tmp_path / "v.SRT")
    assert [f.time for f in track.fixes] == [0.0, 0.05, 0.1, 0.15, 0.2]
    np.testing.assert_allclose([(f.lat, f.lon, f.alt) for f in track.fixes], fixes, atol=1e-9)


def test_subtitles_without_a_fix_are_noted_and_none_at_all_is_an_error(tmp_path):
    text = MAVIC.replace("[latitude: 22.543210] [longitude: 113.954320]", "[latitude: 0.000000] [longitude: 0.000000]")
    text += (
        "\n3\n00:00:00,066 --> 00:00:00,099\n[iso: 3200] [latitude: 95.0] [longitude: 113.9] [rel_alt: 1 abs_alt: 2]\n"
    )
    text += "\n4\n00:00:00,099 --> 00:00:00,133\n[iso: 3200]\n"
    (tmp_path / "a.SRT").write_text(text)
    track = read_srt(tmp_path / "a.SRT")
    assert len(track.fixes) == 1
    assert any("1 subtitle(s) at latitude 0, longitude 0 (no fix yet)" in n for n in track.notes)
    assert any("1 subtitle(s) without a position (the first at 0.099 s)" in n for n in track.notes)
    assert any(n.startswith("a.SRT at 0.066 s: latitude 95 is outside") for n in track.notes)
    (tmp_path / "b.SRT").write_text("1\n00:00:00,000 --> 00:00:00,033\n[iso: 100]\n")
    with pytest.raises(GnssError, match="b.SRT: no subtitle holds a position"):
        read_srt(tmp_path / "b.SRT")
