"""Validation sequences: HPatches-style, exact homographies, the same on every run."""

import cv2
import numpy as np
import skimage.data

from lburst.bench.sequences import list_sequences, read_sequence
from lburst.bench.validation import make_validation_sequences


def _photos(folder):
    folder.mkdir()
    paths = []
    for name in ("astronaut", "coffee"):
        path = folder / f"{name}.png"
        cv2.imwrite(str(path), cv2.cvtColor(getattr(skimage.data, name)()[::2, ::2], cv2.COLOR_RGB2BGR))
        paths.append(path)
    return paths


def test_viewpoint_images_are_image_1_seen_through_the_written_homography(tmp_path):
    folders = make_validation_sequences(_photos(tmp_path / "p"), tmp_path / "v", progress=False)
    assert [f.name[:2] for f in folders] == ["v_", "i_"] and len(list_sequences(tmp_path / "v")) == 2
    seq = read_sequence(folders[0])
    assert seq.kind == "viewpoint"
    angles = []
    for k, h in enumerate(seq.homographies):
        target = seq.images[k + 1].astype(np.float32)
        warped = cv2.warpPerspective(seq.images[0], h, target.shape[1::-1]).astype(np.float32)
        inside = cv2.erode(((warped.sum(2) > 0) & (target.sum(2) > 0)).astype(np.uint8), np.ones((5, 5))) > 0
        assert inside.mean() > 0.3
        assert np.abs(warped - target)[inside].mean() < 6  # two bilinear resamplings, nothing more
        angles.append(np.degrees(np.arctan2(h[1, 0], h[0, 0])))
    assert max(map(abs, angles)) <= 27 and np.std(angles) > 1


def test_illumination_sequences_have_identity_homographies_and_other_light(tmp_path):
    folders = make_validation_sequences(_photos(tmp_path / "p"), tmp_path / "v", progress=False)
    seq = read_sequence(folders[1])
    assert seq.kind == "illumination"
    assert all(np.allclose(h, np.eye(3)) for h in seq.homographies)
    means = [im.mean() for im in seq.images]
    assert max(means) - min(means) > 10


def test_the_set_is_the_same_on_every_run_and_resumes(tmp_path):
    photos = _photos(tmp_path / "p")
    make_validation_sequences(photos, tmp_path / "a", seed=3, progress=False)
    make_validation_sequences(photos, tmp_path / "b", seed=3, progress=False)
    for name in ("v_p_astronaut", "i_p_coffee"):
        for f in ("img4.png", "H1to4p"):
            assert (tmp_path / "a" / name / f).read_bytes() == (tmp_path / "b" / name / f).read_bytes()
    (tmp_path / "a" / "v_p_astronaut" / "img3.png").write_bytes(b"kept")  # finished sequences are not redone
    make_validation_sequences(photos, tmp_path / "a", seed=3, progress=False)
    assert (tmp_path / "a" / "v_p_astronaut" / "img3.png").read_bytes() == b"kept"
