"""A gap in a frame folder's numbering costs the frames there are, not the numbers missing:
one frame numbered 999999999 after 30 frames hung `extract --every 1` (a loop over every
missing index)."""

import builtins

import numpy as np
import pytest

from lburst.burst import sources
from lburst.burst.io import write_image
from lburst.burst.keyframes import MotionGate
from lburst.burst.sources import RecordingOptions, open_recording
from lburst.cli import main

FAR = 999_999_999


@pytest.fixture
def far_frame(tmp_path):
    """Frames 0-29 and one numbered 999999999, textured so that motion finds keyframes."""
    rng = np.random.default_rng(0)
    texture = rng.integers(0, 256, (32, 48 + 4 * 31, 3), dtype=np.uint8)
    folder = tmp_path / "frames"
    folder.mkdir()
    for k, i in enumerate([*range(30), FAR]):
        write_image(folder / f"img_{i}.png", np.ascontiguousarray(texture[:, 4 * k : 4 * k + 48]))
    (folder / "meta.json").write_text('{"fps": 30}')
    return folder


@pytest.fixture
def bounded_loops(monkeypatch):
    """Loops of the keyframe schedule may not step through the missing numbers: ``range`` in
    lburst.burst.sources refuses a long one, and the keyframes tried are counted."""

    def short_range(*args):
        steps = builtins.range(*args)
        if len(steps) > 1000:
            raise AssertionError(f"a loop over {len(steps)} frame indices")
        return steps

    monkeypatch.setattr(sources, "range", short_range, raising=False)
    tried = []
    emit = sources.Recording._emit

    def counted(self, key, buffer):
        tried.append(key)
        if len(tried) > 1000:
            raise AssertionError("over 1000 keyframes tried for 31 frames")
        return emit(self, key, buffer)

    monkeypatch.setattr(sources.Recording, "_emit", counted)
    return tried


@pytest.mark.parametrize("every, start", [(1, 0), (7, 3), (2, 1)])
def test_a_far_frame_number_is_one_step_of_the_schedule(far_frame, bounded_loops, every, start):
    got = list(open_recording(far_frame, RecordingOptions(burst=5, every=every, start=start)).bursts())
    keys = [k.index for k, _ in got]
    on_schedule = [i for i in [*range(30), FAR] if i >= start and (i - start) % every == 0]
    assert keys == on_schedule  # as before: the keyframes whose own frame is there
    if FAR in keys:  # its window holds only itself: filled from it, as any dropped frame
        far, burst = got[-1]
        assert far.filled == 4 and far.name == f"f{FAR}_t{FAR / 30:.3f}s" and (burst == burst[2]).all()
    assert len(bounded_loops) <= 31


def test_a_far_frame_number_with_motion_keyframes(far_frame, bounded_loops):
    keys = [k.index for k, _ in open_recording(far_frame, RecordingOptions(burst=5, motion=MotionGate(0.2))).bursts()]
    assert keys[0] == 0 and len(keys) > 3 and set(keys) <= {*range(30), FAR}


def test_extract_every_1_of_a_folder_with_a_far_frame_number_finishes(far_frame, bounded_loops, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["extract", str(far_frame), "--out", str(out), "--method", "sift", "--every", "1", "--burst", "3"])
    assert code == 0, capsys.readouterr().err
    assert len(list((out / "frames").glob("*.npz"))) == 31
