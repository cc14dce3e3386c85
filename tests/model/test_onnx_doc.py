"""docs/onnx.md's plain ONNX Runtime snippet (the graph, with the steps before and after it written
out) gives the keypoints and descriptors of LBurst.from_onnx at one pyramid level."""

import re
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")
pytest.importorskip("onnxscript")

DOC = Path(__file__).parents[2] / "docs" / "onnx.md"


def _snippet() -> str:
    """The docs' last Python block (the ONNX Runtime one)."""
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)
    assert "onnxruntime" in blocks[-1]
    return blocks[-1]


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    from lburst.model.onnx import export_onnx
    from lburst.weights import weights_path

    return export_onnx(weights_path("lburst-b5"), tmp_path_factory.mktemp("onnx") / "lburst-b5.onnx")


def test_the_docs_onnx_runtime_snippet_matches_lburst_from_onnx(exported, tmp_path):
    from lburst import LBurst, load_burst, simulate_burst
    from lburst.burst.io import save_burst
    from lburst.scenes.textures import load_photo

    photo = np.ascontiguousarray(load_photo("astronaut")[100:228, 120:280])  # 160x128
    save_burst(simulate_burst(photo, 5, motion=(1.5, 0.5), rng=0), tmp_path / "night")
    code = (
        _snippet().replace('"lburst-b5.onnx"', repr(str(exported))).replace('"night/"', repr(str(tmp_path / "night")))
    )
    scope: dict = {}
    exec(compile(code, str(DOC), "exec"), scope)
    keypoints, desc, scores = scope["keypoints"], scope["desc"], scope["scores"]
    assert len(keypoints) > 100 and desc.shape == (len(keypoints), 128)

    burst = load_burst(tmp_path / "night")
    ref = LBurst.from_onnx(exported).extract(burst, top_k=4000, min_size=160, max_size=160)  # one level
    ours = {tuple(k): i for i, k in enumerate(keypoints.tolist())}
    common = [(ours[tuple(k)], j) for j, k in enumerate(ref["keypoints"].tolist()) if tuple(k) in ours]
    assert len(common) >= 0.99 * max(len(keypoints), len(ref["keypoints"]))  # float rounding may move a tie
    i, j = np.array(common).T
    np.testing.assert_allclose(scores[i], ref["scores"][j], atol=1e-5)
    np.testing.assert_allclose(desc[i], ref["descriptors"][j], atol=1e-4)
