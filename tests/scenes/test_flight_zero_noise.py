"""At zero noise both SIFT and the shipped LBurst register every image of the night flight
with a trajectory error below 1% of its length (the whole pipeline against ground truth)."""

import pytest

from lburst.sfm import reconstruct_scene
from lburst.sfm.options import ReconstructOptions


@pytest.fixture(scope="module")
def clean_flight(tmp_path_factory):
    from lburst.scenes.night_flight import NightFlightConfig, make_night_flight

    out = tmp_path_factory.mktemp("clean_flight")
    cfg = NightFlightConfig(n_bursts=10, frames_per_burst=5, width=320, height=240, noise="none")
    make_night_flight(out, cfg, progress=False)
    return out


@pytest.mark.parametrize("method", ["sift", "lburst"])
def test_every_image_registers_at_zero_noise(clean_flight, tmp_path, method):
    result = reconstruct_scene(
        clean_flight,
        method,
        tmp_path / method,
        ReconstructOptions(
            progress=False, camera="reference", fix_intrinsics=True, pairs="sequential", overlap=4, num_threads=1
        ),
    )  # one thread: the same result on a busy or an idle machine
    assert result.error is None and result.registered == result.names
    assert result.metrics["ate_percent"] < 1.0
