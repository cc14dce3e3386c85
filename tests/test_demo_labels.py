"""The demo's method labels name each method's table row and output folder: no two may clash."""

from lburst.demo import method_labels
from lburst.methods import Method


def test_two_lburst_checkpoints_get_their_own_labels():
    specs = [
        "lburst",
        "lburst:../shared/anchors/RoBLo_N16_B5.pt,frame_order=published",
        "merge+r2d2",
        "lburst:runs/a/last.pt",
        "lburst:runs/b/last.pt",
        "sift",
    ]
    labels = {str(method): label for method, label in method_labels([Method.parse(s) for s in specs]).items()}
    assert len(set(labels.values())) == len(specs)
    assert labels["lburst"] == "lburst"
    assert labels[specs[1]] == "lburst-RoBLo_N16_B5-frame_order=published"
    assert all("/" not in lab for lab in labels.values())
