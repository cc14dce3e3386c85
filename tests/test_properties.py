"""Property-based tests: for random input, every outcome is a result or a documented error
with a message (``BurstError``/``ValueError``), never a hang, a native crash or a wrong
result.  The default run is bounded (a few dozen examples per target); set
``LBURST_HYPOTHESIS_EXAMPLES`` for a long run, e.g. 2000."""

import math
import os

import cv2
import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, example, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from hypothesis.extra import numpy as hnp  # noqa: E402

from lburst.burst.io import BurstError, load_burst  # noqa: E402
from lburst.model.extractor import MAX_LEVELS, LBurst, MultiScaleConfig  # noqa: E402
from lburst.model.network import LBurstNet, NetConfig  # noqa: E402

EXAMPLES = int(os.environ.get("LBURST_HYPOTHESIS_EXAMPLES", "40"))
SETTINGS = settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
NET = LBurst(LBurstNet(NetConfig(frames=1)))


@SETTINGS
@given(data=st.binary(max_size=4096), suffix=st.sampled_from([".png", ".jpg", ".tif", ".bmp", ".webp", ".pgm"]))
def test_any_file_bytes_load_or_raise_a_burst_error(tmp_path_factory, data, suffix):
    path = tmp_path_factory.mktemp("bytes") / f"frame{suffix}"
    path.write_bytes(data)
    try:
        burst = load_burst(path)
    except BurstError as err:
        assert str(path) in str(err)
    else:
        assert burst.ndim == 4 and burst.shape[-1] == 3 and burst.dtype in (np.uint8, np.uint16)


@SETTINGS
@given(
    image=hnp.arrays(st.sampled_from([np.uint8, np.uint16]), st.tuples(st.integers(1, 40), st.integers(1, 40))),
    keep=st.floats(0.05, 1.0),
)
@example(image=np.zeros((1, 1), np.uint8), keep=0.25).via("a PNG cut inside its IHDR chunk")
def test_truncated_encodings_never_load_as_a_partial_frame(tmp_path_factory, image, keep):
    folder = tmp_path_factory.mktemp("enc")
    for suffix in (".png", ".jpg"):
        if suffix == ".jpg" and image.dtype != np.uint8:
            continue
        ok, data = cv2.imencode(suffix, image)
        whole = data.tobytes()
        path = folder / f"f{suffix}"
        path.write_bytes(whole[: max(1, int(len(whole) * keep))])
        try:
            burst = load_burst(path)
        except BurstError:
            continue
        if keep < 1.0 and suffix == ".jpg":
            pytest.fail("a truncated JPEG loaded")
        if keep == 1.0 and suffix == ".png":
            np.testing.assert_array_equal(burst[0, ..., 0], image)


finite = st.floats(allow_nan=True, allow_infinity=True, width=32)


@SETTINGS
@given(
    min_size=st.one_of(st.integers(-5, 600), finite),
    max_size=st.integers(-5, 2000),
    scale_factor=st.one_of(finite, st.integers(-2, 4)),
    rel_thr=finite,
    rep_thr=finite,
    top_k=st.one_of(st.none(), st.integers(-3, 5000), finite, st.booleans()),
)
@example(min_size=1, max_size=1, scale_factor=2, rel_thr=0.0, rep_thr=1.0, top_k=0).via("every lower bound")
@example(min_size=0, max_size=1, scale_factor=2, rel_thr=0.5, rep_thr=0.5, top_k=None).via("min_size below 1")
@example(min_size=2, max_size=1, scale_factor=2, rel_thr=0.5, rep_thr=0.5, top_k=None).via("max_size below min_size")
@example(min_size=1, max_size=1, scale_factor=1, rel_thr=0.5, rep_thr=0.5, top_k=None).via("scale_factor at 1")
@example(min_size=1, max_size=1, scale_factor=2, rel_thr=1.0000001, rep_thr=0.5, top_k=None).via("rel_thr above 1")
@example(min_size=1, max_size=1, scale_factor=2, rel_thr=0.5, rep_thr=-1e-9, top_k=None).via("rep_thr below 0")
@example(min_size=1, max_size=1, scale_factor=2, rel_thr=0.5, rep_thr=0.5, top_k=-1).via("top_k below 0")
@example(min_size=1, max_size=2**63, scale_factor=2, rel_thr=0.5, rep_thr=0.5, top_k=None).via("64 levels")
@example(min_size=1, max_size=2**64, scale_factor=2, rel_thr=0.5, rep_thr=0.5, top_k=None).via("65 levels")
def test_multiscale_settings_are_valid_or_a_value_error(min_size, max_size, scale_factor, rel_thr, rep_thr, top_k):
    def integer(v):
        return isinstance(v, int) and not isinstance(v, bool)

    def real(v):
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

    valid = (
        integer(min_size)
        and integer(max_size)
        and 1 <= min_size <= max_size
        and real(scale_factor)
        and scale_factor > 1
        and all(real(v) and 0 <= v <= 1 for v in (rel_thr, rep_thr))
        and (top_k is None or (integer(top_k) and top_k >= 0))
    )
    valid = valid and 1 + math.log(max_size / min_size) / math.log(scale_factor) <= MAX_LEVELS
    if not valid:
        with pytest.raises(ValueError, match="."):
            MultiScaleConfig(
                min_size=min_size,
                max_size=max_size,
                scale_factor=scale_factor,
                rel_thr=rel_thr,
                rep_thr=rep_thr,
                top_k=top_k,
            )
        return
    cfg = MultiScaleConfig(
        min_size=min_size, max_size=max_size, scale_factor=scale_factor, rel_thr=rel_thr, rep_thr=rep_thr, top_k=top_k
    )
    assert (cfg.min_size, cfg.max_size, cfg.scale_factor, cfg.rel_thr, cfg.top_k) == (
        min_size,
        max_size,
        scale_factor,
        rel_thr,
        top_k,
    )


@SETTINGS
@given(
    shape=st.tuples(st.integers(1, 48), st.integers(1, 48)),
    dtype=st.sampled_from([np.uint8, np.uint16, np.float32, np.float64, np.int32, np.bool_]),
    scale=st.sampled_from([1.0, 255.0, np.nan, np.inf]),
    options=st.fixed_dictionaries(
        {},
        optional={
            "min_size": st.integers(1, 64),
            "scale_factor": st.floats(1.05, 3.0),
            "top_k": st.integers(0, 50),
            "rel_thr": st.floats(0, 1),
            "rep_thr": st.floats(0, 1),
        },
    ),
)
def test_extract_gives_features_or_a_value_error(shape, dtype, scale, options):
    rng = np.random.default_rng(0)
    image = rng.uniform(0, 1, (*shape, 3))
    if np.issubdtype(dtype, np.floating):
        image = (image * scale).astype(dtype)
    elif dtype == np.bool_:
        image = image > 0.5
    else:
        image = (image * np.iinfo(dtype).max).astype(dtype)
    try:
        feats = NET.extract(image, **options)
    except ValueError as err:
        assert str(err)
        return
    assert np.isfinite(feats["keypoints"]).all() and np.isfinite(feats["descriptors"]).all()
    k = len(feats["keypoints"])
    assert k <= options.get("top_k", 4000) and feats["descriptors"].shape == (k, 128)
    assert (feats["keypoints"] >= -0.5).all() and (feats["keypoints"][:, 0] <= shape[1] - 0.5).all()


@SETTINGS
@given(
    spec=st.one_of(
        st.text(alphabet="abcefhilmnorstu:=,+ 0123456789._-", max_size=40),
        st.builds(
            lambda name, pairs: name + "".join(f",{k}={v}" for k, v in pairs),
            st.sampled_from(["sift", "orb", "merge+sift", "buff", "lburst", "r2d2"]),
            st.lists(
                st.tuples(
                    st.sampled_from(["top_k", "scale_factor", "min_size", "rel_thr", "max_features", "reduce", "nope"]),
                    st.sampled_from(["-1", "0", "1", "1.0", "0.5", "x", "none", ""]),
                ),
                max_size=2,
            ),
        ),
    )
)
def test_method_specs_create_an_extractor_or_raise_a_value_error(spec):
    from lburst.methods import create

    try:
        extractor = create(spec, device="cpu") if spec.split("+")[-1].startswith(("lburst", "r2d2")) else create(spec)
    except ValueError as err:
        assert str(err)
        return
    assert callable(extractor) and extractor.name
