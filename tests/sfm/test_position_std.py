"""``--position-std`` reaches COLMAP: the job the COLMAP child reads holds the priors with it."""

import pytest

from lburst.cli import main
from lburst.scenes.night_flight import NightFlightConfig, gnss_positions, make_night_flight
from lburst.sfm import mapping as mapping_module
from lburst.sfm.colmap import ColmapError, ColmapJob
from lburst.sfm.positions import write_positions


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """Three single-frame bursts of the daylight flight, 128x96, and a receiver's log."""
    out = tmp_path_factory.mktemp("flight")
    cfg = NightFlightConfig.daylight(n_bursts=3, frames_per_burst=1, width=128, height=96, noise="none")
    make_night_flight(out, cfg, progress=False)
    write_positions(out / "gnss.txt", gnss_positions(cfg, 0.5))
    return out


@pytest.mark.parametrize("std", ["0.7", "13"])
def test_the_position_std_given_on_the_command_line_is_the_std_of_the_priors_colmap_reads(
    scene, tmp_path, monkeypatch, std
):
    def stop(job_dir, **_):  # the job as written for the COLMAP child; COLMAP itself need not run
        raise ColmapError("stopped before COLMAP")

    monkeypatch.setattr(mapping_module, "run_job_subprocess", stop)
    out = tmp_path / "out"
    argv = ["reconstruct", str(scene), "--method", "sift,max_features=300", "--out", str(out), "--threads", "1"]
    assert main([*argv, "--positions", str(scene / "gnss.txt"), "--position-std", std]) == 1  # COLMAP "failed"
    job = ColmapJob.load(out / "colmap" / "job.json")
    assert job.position_std == float(std)
    assert job.positions is not None and all(p is not None and len(p) == 3 for p in job.positions)
