"""A training step's memory is estimated before the first batch: a batch that cannot fit is
refused with the figure and the option that lowers it, before any folder or allocation."""

import cv2
import pytest
import skimage.data

from lburst.model.extractor import memory_limit_bytes
from lburst.train.loop import TrainConfig, build_network, train
from lburst.train.memory import BASE_BYTES, activations_per_pixel, check_step_memory, step_bytes
from lburst.train.pairs import PairConfig


def test_the_estimate_grows_with_the_batch_and_the_crop_area():
    net = build_network("lburst", 5)
    one, four = step_bytes(net, 15, 1, 192) - BASE_BYTES, step_bytes(net, 15, 4, 192) - BASE_BYTES
    assert four == pytest.approx(4 * one, rel=1e-6)
    assert step_bytes(net, 15, 1, 384) - BASE_BYTES == pytest.approx(4 * one, rel=1e-6)
    # measured peak of one bf16 step at batch 16 (module docstring): 5.8 GB
    assert 5.0e9 < step_bytes(net, 15, 16, 192) < 6.6e9


def test_the_light_network_counts_fewer_activations():
    assert activations_per_pixel(build_network("lite", 5), 15) < 0.3 * activations_per_pixel(
        build_network("lburst", 5), 15
    )


def test_a_batch_over_the_limit_is_refused_with_the_figure_and_the_option():
    net = build_network("lburst", 5)
    check_step_memory(net, 15, 4, 192, limit=4 * 2**30)
    with pytest.raises(
        ValueError, match=r"--batch-size 64: .* needs about 2\d\.\d GiB.*lower --batch-size \(about \d+ fit\)"
    ):
        check_step_memory(net, 15, 64, 192, limit=4 * 2**30)


@pytest.mark.skipif(memory_limit_bytes() is None, reason="the OS does not report its memory")
def test_train_refuses_before_it_creates_the_run_folder(tmp_path):
    folder = tmp_path / "photos"
    folder.mkdir()
    cv2.imwrite(str(folder / "a.png"), cv2.cvtColor(skimage.data.astronaut(), cv2.COLOR_RGB2BGR))
    huge = TrainConfig(frames=3, batch_size=512, steps=1, workers=0, pair=PairConfig(frames=3, crop=1024))
    with pytest.raises(ValueError, match="--batch-size 512"):
        train([folder], tmp_path / "run", huge, progress=False)
    assert not (tmp_path / "run").exists()
