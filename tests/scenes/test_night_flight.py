"""Geometry of the synthetic night flight against its own ground truth."""

from __future__ import annotations

import dataclasses
import json

import cv2
import numpy as np
import pytest

from lburst.cli import simulate_flight as flight_command
from lburst.scenes import night_flight as nf
from lburst.scenes.city import BUILDING, City, CityConfig
from lburst.scenes.raycast import intrinsics
from lburst.scenes.textures import MipTexture
from lburst.sfm.reference import Reference

RED, BLUE, GREY = (255.0, 0.0, 0.0), (0.0, 0.0, 255.0), (100.0, 100.0, 100.0)
# small images and a coarse ground texture keep the tests fast
SMALL = dict(width=160, height=120, city=CityConfig(ground_texel=0.25, wall_texel=0.1, roof_texel=0.2))


def chord(cfg: nf.NightFlightConfig, arc: float) -> float:
    """Straight-line distance between two points ``arc`` metres apart on the flight's circular path."""
    kappa = np.radians(cfg.turn_deg) / ((cfg.n_bursts - 1) * cfg.burst_spacing)
    return 2 * np.sin(kappa * arc / 2) / kappa


def one_box_city(lo, hi) -> City:
    """Grey ground, one box with a red roof and blue walls."""
    return City(
        lo=np.array([lo], float),
        hi=np.array([hi], float),
        kind=np.array([BUILDING]),
        ground=MipTexture.constant(GREY),
        origin=np.zeros(2),
        ground_texel=1.0,
        roof=MipTexture.constant(RED),
        roof_texel=1.0,
        wall=MipTexture.constant(BLUE),
        wall_texel=1.0,
        box_uv=np.zeros((1, 3, 2)),
        box_gain=np.ones((1, 3), np.float32),
        lamp_colour=np.full(3, 255.0, np.float32),
        sky=np.zeros(3, np.float32),
    )


def polygon_distance(polygon: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Signed distance bound of ``points`` (N, 2) to the convex hull of ``polygon``:
    > e means inside by more than e, < -e outside by more than e."""
    hull = cv2.convexHull(polygon.astype(np.float32)).reshape(-1, 2).astype(np.float64)
    a, b = hull, np.roll(hull, -1, axis=0)
    edge = b - a
    normal = np.stack([-edge[:, 1], edge[:, 0]], 1) / np.linalg.norm(edge, axis=1, keepdims=True)
    if np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]) < 0:
        normal = -normal
    return ((points[:, None, :] - a[None]) * normal[None]).sum(-1).min(1)


def classify(image: np.ndarray, colour) -> np.ndarray:
    return np.all(np.abs(image - np.asarray(colour)) < 1.0, axis=-1)


@pytest.mark.parametrize("burst", [0, 2])
def test_box_lands_where_reference_projects_it(burst):
    """Pixel centres inside the projected roof are red, inside the projected box are red
    or blue, outside are grey, exactly (no anti-aliasing), in COLMAP's pixel convention."""
    cfg = nf.NightFlightConfig(n_bursts=3, **SMALL)
    ref = nf.reference(cfg)
    name = nf.burst_name(burst)
    R, t = ref.poses[name]
    K = ref.intrinsics()
    # a box standing on the ground point seen at the image centre
    centre = -R.T @ t
    ray = R.T @ np.linalg.inv(K) @ np.array([cfg.width / 2, cfg.height / 2, 1.0])
    ground = centre + ray * (-centre[2] / ray[2])
    lo, hi = ground + [-6.0, -4.0, 0.0], ground + [5.0, 7.0, 12.0]
    city = one_box_city([lo[0], lo[1], 0.0], [hi[0], hi[1], 12.0])
    image, depth = nf.render_view(city, K, R, t, cfg.width, cfg.height)

    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (0.0, 12.0)])
    uv = ref.project(name, corners)
    roof_uv = ref.project(name, corners[corners[:, 2] > 0])
    jj, ii = np.meshgrid(np.arange(cfg.width), np.arange(cfg.height))
    centres = np.stack([jj + 0.5, ii + 0.5], -1).reshape(-1, 2)  # COLMAP: top-left centre (0.5, 0.5)
    d_box = polygon_distance(uv, centres).reshape(cfg.height, cfg.width)
    d_roof = polygon_distance(roof_uv, centres).reshape(cfg.height, cfg.width)
    eps = 1e-3
    red, blue, grey = classify(image, RED), classify(image, BLUE), classify(image, GREY)
    assert np.all(red[d_roof > eps])
    assert np.all((red | blue)[d_box > eps])
    assert np.all(grey[d_box < -eps])
    assert np.all(~red[d_roof < -eps])
    assert (np.abs(d_box) < 0.5).sum() > 50, "the box edge should cross many pixels"
    # the check is sharp: the same silhouette half a pixel off disagrees with the render
    shifted = polygon_distance(uv + 0.5, centres).reshape(cfg.height, cfg.width)
    assert not np.all(grey[shifted < -eps])
    # depth of the roof is the camera-frame z of the roof plane point
    i, j = np.argwhere(d_roof > 1)[0]
    ray = np.linalg.inv(K) @ np.array([j + 0.5, i + 0.5, 1.0])
    world = centre + (R.T @ ray) * (12.0 - centre[2]) / (R.T @ ray)[2]
    np.testing.assert_allclose(depth[i, j], (R @ world + t)[2], rtol=1e-6)  # boxes are cast in float32


def test_burst_frames_follow_the_flight():
    """Frame poses are spaced by speed * frame_interval along the path, the middle one is
    the reference pose, and the heading points along the motion."""
    cfg = nf.NightFlightConfig(n_bursts=4, frames_per_burst=5, speed=6.0, frame_interval=0.1, **SMALL)
    poses = nf.burst_poses(cfg, 2)
    centres = np.array([-R.T @ t for R, t in poses])
    steps = np.linalg.norm(np.diff(centres, axis=0), axis=1)
    np.testing.assert_allclose(steps, chord(cfg, 0.6), rtol=1e-9)
    np.testing.assert_allclose(centres[:, 2], cfg.altitude)
    R_ref, t_ref = nf.reference(cfg).poses["0002"]
    np.testing.assert_allclose(poses[2][0], R_ref)
    np.testing.assert_allclose(poses[2][1], t_ref)
    # optical axis: pitch_deg from nadir, tilted towards the direction of flight
    axis = poses[2][0][2]
    assert np.degrees(np.arccos(-axis[2])) == pytest.approx(cfg.pitch_deg, abs=2 * cfg.shake_deg)
    motion = centres[3] - centres[1]
    assert axis[:2] @ motion[:2] > 0.9 * np.linalg.norm(axis[:2]) * np.linalg.norm(motion[:2])
    # common frames are burst_spacing apart along the path, which turns by turn_deg
    ref = nf.reference(cfg)
    ref_centres = np.array(list(ref.centers().values()))
    np.testing.assert_allclose(
        np.linalg.norm(np.diff(ref_centres, axis=0), axis=1), chord(cfg, cfg.burst_spacing), rtol=1e-9
    )
    first, last = (ref.poses[n][0][2][:2] for n in ("0000", "0003"))
    turn = np.degrees(np.arctan2(first[0] * last[1] - first[1] * last[0], first @ last))
    # the wobble tilts the axis by <= ~0.5 deg, which moves its azimuth by up to 0.5 / sin(pitch)
    assert turn == pytest.approx(cfg.turn_deg, abs=2 * 0.5 / np.sin(np.radians(cfg.pitch_deg)))


def test_burst_frames_have_parallax_consistent_with_the_poses():
    """Warping the last frame into the first with the true depth and poses reproduces it;
    no single 2D shift does (the frames are not a translated copy)."""
    cfg = nf.NightFlightConfig.daylight(n_bursts=2, frame_interval=0.2, **SMALL)
    city = nf.make_city(cfg)
    K = intrinsics(cfg.width, cfg.height, cfg.hfov_deg)
    (R0, t0), *_, (R4, t4) = nf.burst_poses(cfg, 1)
    first, depth0 = nf.render_view(city, K, R0, t0, cfg.width, cfg.height)
    last, depth4 = nf.render_view(city, K, R4, t4, cfg.width, cfg.height)
    jj, ii = np.meshgrid(np.arange(cfg.width) + 0.5, np.arange(cfg.height) + 0.5)
    cam4 = np.stack([jj, ii, np.ones_like(jj)], -1) @ np.linalg.inv(K).T * depth4[..., None]
    cam0 = (cam4 - t4) @ R4 @ R0.T + t0
    uv0 = cam0[..., :2] / cam0[..., 2:] * np.diag(K)[:2] + K[:2, 2]
    flow = uv0 - np.stack([jj, ii], -1)
    assert flow.reshape(-1, 2).std(0).max() > 0.3, "frames should differ by more than a 2D shift"
    assert np.linalg.norm(np.median(flow.reshape(-1, 2), 0)) > 1.0, "the drone should move during the burst"
    maps = (uv0 - 0.5).astype(np.float32)  # OpenCV: top-left centre at (0, 0)
    warped = cv2.remap(
        first, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=-1
    )
    seen = cv2.remap(depth0.astype(np.float32), maps[..., 0], maps[..., 1], cv2.INTER_NEAREST, borderValue=-1)
    valid = (warped.min(-1) >= 0) & (np.abs(seen - cam0[..., 2]) < 0.01 * cam0[..., 2])
    assert valid.mean() > 0.8
    error = np.abs(warped - last).mean(-1)[valid]
    shift = np.median(flow[valid], 0)
    moved = cv2.warpAffine(first, np.array([[1, 0, -shift[0]], [0, 1, -shift[1]]]), (cfg.width, cfg.height))
    shift_error = np.abs(moved - last).mean(-1)[valid]
    assert np.median(error) < 3.0
    assert np.mean(error) < 0.5 * np.mean(shift_error)


def test_consecutive_common_frames_overlap():
    cfg = nf.NightFlightConfig(n_bursts=4, **SMALL)
    overlaps = nf.view_overlaps(cfg)
    assert overlaps.shape == (3,)
    assert np.all(overlaps > 0.65) and np.all(overlaps < 0.99)
    far = dataclasses.replace(cfg, burst_spacing=60.0)
    assert np.all(nf.view_overlaps(far) < 0.3)


def test_rendering_is_deterministic_and_seeded():
    cfg = nf.NightFlightConfig(n_bursts=2, frames_per_burst=3, **SMALL)
    a = nf.render_burst(cfg, 1)
    assert a.shape == (3, 120, 160, 3) and a.dtype == np.uint8
    np.testing.assert_array_equal(a, nf.render_burst(cfg, 1))
    other = nf.render_burst(dataclasses.replace(cfg, seed=1), 1)
    assert np.abs(a.astype(int) - other).mean() > 10
    assert np.abs(a[0].astype(int) - a[2]).mean() > 2, "frames of a burst should differ"
    dim = nf.render_burst(dataclasses.replace(cfg, exposure=0.25), 1)
    unsaturated = a < 250
    np.testing.assert_allclose(dim[unsaturated], a[unsaturated] * 0.25, atol=0.5 + 0.125)  # two roundings


def test_noise_is_seeded_per_frame():
    pytest.importorskip("lburst.noise")
    cfg = nf.NightFlightConfig(n_bursts=1, frames_per_burst=3, noise="gaussian:20", **SMALL)
    city = nf.make_city(cfg)
    a = nf.render_burst(cfg, 0, city)
    np.testing.assert_array_equal(a, nf.render_burst(cfg, 0, city))
    clean = nf.render_burst(cfg, 0, city, noisy=False)
    residual = a.astype(float) - clean
    assert 10 < residual.std() < 25
    assert np.abs(residual[0] - residual[1]).mean() > 5, "each frame draws its own noise"


def test_make_night_flight_writes_and_resumes(tmp_path):
    cfg = nf.NightFlightConfig(n_bursts=3, frames_per_burst=3, width=64, height=48, city=SMALL["city"])
    out = tmp_path / "scene"
    ref = nf.make_night_flight(out, cfg, progress=False)
    assert sorted(p.name for p in out.iterdir()) == ["0000", "0001", "0002", "night_flight.json", "reference.json"]
    assert sorted(p.name for p in (out / "0001").iterdir()) == ["frame_000.png", "frame_001.png", "frame_002.png"]
    frame = cv2.imread(str(out / "0001" / "frame_001.png"), cv2.IMREAD_UNCHANGED)
    assert frame.shape == (48, 64, 3) and frame.dtype == np.uint8
    np.testing.assert_array_equal(frame[..., ::-1], nf.clean_common_frames(cfg)["0001"])
    loaded = Reference.load(out / "reference.json")
    assert loaded.source == "synthetic" and loaded.camera["params"] == [
        pytest.approx(v) for v in [55.4256, 55.4256, 32.0, 24.0]
    ]
    assert loaded.length == pytest.approx(2 * chord(cfg, cfg.burst_spacing), rel=1e-9)
    np.testing.assert_allclose(loaded.poses["0002"][1], ref.poses["0002"][1])
    assert nf.NightFlightConfig.from_dict(json.loads((out / "night_flight.json").read_text())) == cfg

    # resume: kept bursts are not rewritten, a missing one is rendered again
    mtime = (out / "0000" / "frame_000.png").stat().st_mtime_ns
    for p in (out / "0002").iterdir():
        p.unlink()
    (out / "0002").rmdir()
    nf.make_night_flight(out, cfg, progress=False)
    assert (out / "0000" / "frame_000.png").stat().st_mtime_ns == mtime
    assert len(list((out / "0002").iterdir())) == 3
    assert not [p for p in out.iterdir() if p.name.startswith(".")]

    with pytest.raises(ValueError, match="another configuration"):
        nf.make_night_flight(out, dataclasses.replace(cfg, seed=5), progress=False)


def test_bad_configuration_is_refused():
    with pytest.raises(ValueError, match="odd"):
        nf.NightFlightConfig(frames_per_burst=4)
    with pytest.raises(ValueError, match="horizon"):
        nf.NightFlightConfig(pitch_deg=75)


def test_command_line(tmp_path, capsys):
    import argparse

    parser = argparse.ArgumentParser()
    flight_command.configure_parser(parser)
    out = tmp_path / "flight"
    assert (
        flight_command.main(
            parser.parse_args([str(out), "--bursts", "2", "--frames", "3", "--size", "48x32", "--daylight"])
        )
        == 0
    )
    assert Reference.load(out / "reference.json").camera["width"] == 48
    assert len(list((out / "0001").glob("frame_*.png"))) == 3
    capsys.readouterr()
    with pytest.raises(ValueError, match="odd"):  # the command raises; lburst.cli.main prints it
        flight_command.main(parser.parse_args([str(out), "--frames", "4"]))
    from lburst.cli import main

    assert main(["simulate", "flight", str(out), "--frames", "4"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lburst simulate flight: error: ") and "odd" in err[0], err


@pytest.mark.slow
def test_colmap_sift_registers_the_clean_flight(tmp_path):
    """COLMAP's own SIFT pipeline registers every clean common frame of the default flight,
    and its camera centres match the ground truth up to a similarity (about 70 s)."""
    pycolmap = pytest.importorskip("pycolmap")
    from lburst.sfm.poses import umeyama

    cfg = nf.NightFlightConfig()
    ref = nf.reference(cfg)
    images = tmp_path / "images"
    images.mkdir()
    for name, frame in nf.clean_common_frames(cfg).items():
        cv2.imwrite(str(images / f"{name}.png"), frame[..., ::-1])
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = "PINHOLE"
    reader.camera_params = ",".join(str(v) for v in ref.camera["params"])
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = 1
    database = tmp_path / "database.db"
    pycolmap.extract_features(
        database,
        images,
        camera_mode=pycolmap.CameraMode.SINGLE,
        reader_options=reader,
        extraction_options=extraction,
        device=pycolmap.Device.cpu,
    )
    pycolmap.match_exhaustive(database, device=pycolmap.Device.cpu)
    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = 1
    options.ba_refine_focal_length = False
    options.ba_refine_principal_point = False
    options.ba_refine_extra_params = False
    models = pycolmap.incremental_mapping(database, images, tmp_path / "sparse", options=options)
    model = max(models.values(), key=lambda m: m.num_reg_images())
    assert model.num_reg_images() == cfg.n_bursts
    estimated = {image.name[:-4]: image.projection_center() for image in model.images.values()}
    names = sorted(ref.poses)
    source = np.array([estimated[n] for n in names])
    target = np.array([ref.centers()[n] for n in names])
    errors = np.linalg.norm(umeyama(source, target).apply(source) - target, axis=1)
    assert np.sqrt(np.mean(errors**2)) < 0.001 * ref.length
