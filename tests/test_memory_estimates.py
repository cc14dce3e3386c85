"""Sizes are estimated before they are allocated: a flight's city and frames, a network's weights
and maps, an image from its header, SIFT's scale space, a local cluster's workers; each refusal
is one line with the figure and what lowers it.  The machine's memory is pinned (8 GiB for half
of it) so that the figures do not depend on where the tests run."""

import struct
import zlib

import numpy as np
import pytest

import lburst.memory
from lburst.burst.io import BurstError, load_burst, read_image, save_burst
from lburst.cli import main
from lburst.memory import GIB, check_memory
from lburst.model.lite import LiteNet
from lburst.model.network import CheckpointError, checkpoint_dict, load_checkpoint, network_from_net_string
from lburst.scenes import night_flight
from lburst.scenes.night_flight import NightFlightConfig, check_flight_memory
from lburst.train.loop import build_network


@pytest.fixture
def half_memory(monkeypatch):
    """Half of the machine's memory is 8 GiB, whatever the machine."""
    monkeypatch.setattr(lburst.memory, "memory_limit_bytes", lambda: 8 * GIB)


@pytest.fixture
def no_city(monkeypatch):
    """Building a city fails the test: a refused flight must stop before it."""

    def built(*args, **kwargs):
        raise AssertionError("the city was built")

    monkeypatch.setattr(night_flight, "build_city", built)


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    return err


def test_check_memory_names_the_figure_the_limit_and_the_remedy():
    check_memory(GIB, "a thing", "use less", limit=GIB)
    with pytest.raises(ValueError) as err:
        check_memory(3 * GIB, "a thing", "use less", limit=GIB)
    assert str(err.value) == "a thing needs about 3.0 GiB, more than half of this machine's memory (1.0 GiB): use less"


@pytest.mark.parametrize(
    "options, remedy",
    [
        (["--spacing", "1000"], "--spacing"),
        (["--size", "100000x100000"], "--size"),
        (["--survey", "1000", "--line-length", "10000"], "--line-length"),
    ],
)
def test_simulate_flight_refuses_what_would_not_fit_before_writing(
    tmp_path, capsys, half_memory, no_city, options, remedy
):
    out = tmp_path / "flight"
    assert main(["simulate", "flight", str(out), *options]) == 2
    err = _one_error_line(capsys)
    assert "GiB, more than half of this machine's memory (8.0 GiB)" in err and remedy in err
    assert not out.exists()


def test_the_flight_estimate_follows_the_path_and_the_frame(half_memory):
    check_flight_memory(NightFlightConfig())  # the demo's flight fits
    city, frame, _ = night_flight.flight_bytes(NightFlightConfig())
    longer, _, _ = night_flight.flight_bytes(NightFlightConfig(n_bursts=40))
    _, bigger, _ = night_flight.flight_bytes(NightFlightConfig(width=1280, height=960))
    assert 0.3 * GIB < city < 0.6 * GIB  # 447 MiB measured for the default flight
    assert longer > 2 * city and bigger == pytest.approx(4 * frame)


def test_a_light_network_too_big_for_memory_is_refused_before_it_is_built(half_memory, tmp_path):
    with pytest.raises(
        CheckpointError, match=r"LBurstLite\(dim=2000000000\) \(its weights alone\) needs about 72\d\.\d GiB"
    ):
        network_from_net_string("LBurstLite(dim=2000000000)")
    checkpoint = checkpoint_dict(LiteNet())
    checkpoint["net"] = "LBurstLite(inchan=15,dim=2000000000,fine=32,coarse=96,dilations=1-2-4-8)"
    torch = pytest.importorskip("torch")
    torch.save(checkpoint, tmp_path / "huge.pt")
    with pytest.raises(CheckpointError, match=r"huge.pt: .*needs about .* GiB.*: a smaller network \(lower dim"):
        load_checkpoint(tmp_path / "huge.pt")
    with pytest.raises(ValueError, match=r"--arch 'LBurstLite\(dim=2000000000\)' \(its weights alone\)"):
        build_network("LBurstLite(dim=2000000000)", 5)


def test_a_light_network_whose_maps_would_not_fit_is_refused(monkeypatch):
    monkeypatch.setattr(lburst.memory, "memory_limit_bytes", lambda: GIB)
    with pytest.raises(CheckpointError, match=r"on a 1024x768 input \(its weights 0.0 GiB\) needs about [1-9]"):
        network_from_net_string("LBurstLite(dim=20000)")
    assert isinstance(network_from_net_string("LBurstLite(dim=128)"), LiteNet)


def _png_header(path, width, height):
    """A PNG file that says it is ``width x height`` (8-bit RGB) and holds no pixels: a decoder
    would have to allocate the whole image before finding out."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b"")
    )
    return path


def test_an_image_is_sized_from_its_header_before_it_is_decoded(tmp_path, half_memory):
    big = _png_header(tmp_path / "big.png", 25000, 25000)
    with pytest.raises(BurstError, match=r"big.png: a 25000x25000 image needs about 12.8 GiB.*: resize the images"):
        read_image(big)
    with pytest.raises(BurstError, match="25000x25000 image needs about"):
        load_burst(big)
    folder = tmp_path / "burst"
    folder.mkdir()
    for k in range(3):
        _png_header(folder / f"frame_{k}.png", 17000, 17000)  # one fits, three held together do not
    with pytest.raises(BurstError, match=r"burst: 3 frames of 17000x17000 needs about 9.2 GiB"):
        load_burst(folder)


def test_extract_of_a_huge_png_with_sift_is_one_line(tmp_path, capsys, half_memory):
    big = _png_header(tmp_path / "big.png", 25000, 25000)
    assert main(["extract", str(big), "--out", str(tmp_path / "out"), "--method", "sift"]) == 1  # skipped
    assert "big.png: a 25000x25000 image needs about 12.8 GiB" in capsys.readouterr().err


@pytest.mark.parametrize("method", ["sift", "orb"])
def test_opencv_detectors_estimate_their_scale_space(monkeypatch, method):
    monkeypatch.setattr(lburst.memory, "memory_limit_bytes", lambda: 500 * 400 * 240 - 1)
    burst = np.zeros((1, 400, 500, 3), np.uint8)
    with pytest.raises(ValueError, match=rf"{method.upper()} on a 500x400 frame needs about"):
        lburst.methods.create(method)(burst)
    monkeypatch.setattr(lburst.memory, "memory_limit_bytes", lambda: 500 * 400 * 240)
    assert lburst.methods.create(method)(burst)["image_size"].tolist() == [500, 400]


def test_a_local_cluster_larger_than_the_machine_is_refused_before_it_starts(tmp_path, capsys, monkeypatch):
    distributed = pytest.importorskip("distributed")
    from lburst.cluster import session

    monkeypatch.setattr(session, "usable_cores", lambda: 2)
    monkeypatch.setattr(lburst.memory, "memory_limit_bytes", lambda: 8 * GIB)

    def started(*args, **kwargs):
        raise AssertionError("a local cluster was started")

    monkeypatch.setattr(distributed, "LocalCluster", started)
    burst = tmp_path / "b0"
    save_burst(np.zeros((1, 32, 32, 3), np.uint8), burst)
    assert (
        main(["extract", str(burst), "--out", str(tmp_path / "out"), "--cluster", "local:64", "--method", "sift"]) == 2
    )
    err = _one_error_line(capsys)
    assert err.endswith("this machine has 2 cores, half its memory 8.0 GiB: use local:2 or fewer"), err
    monkeypatch.setattr(lburst.memory, "memory_limit_bytes", lambda: GIB)  # two cores, memory for two workers
    with pytest.raises(ValueError, match="use local:2 or fewer"):
        session.check_local_workers(3)
    session.check_local_workers(2)
