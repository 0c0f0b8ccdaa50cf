"""COCO-C noise and blur corruptions on the chart SNR and MTF50 scales: seeding, the chart
calibration (monotone in severity, closed forms), the results table, the CLI."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.special import erf
from scipy.stats import norm

from fidelity.cli import main
from fidelity.coco import corruptions as cc
from fidelity.coco import spatial as sp
from fidelity.colour import colorimetry as cm
from fidelity.prediction.properties import load_property_table, predict_property

ROOT = Path(__file__).resolve().parents[2]
#: Luminance weights of linear sRGB (the chart measurement's Y).
WEIGHTS = np.array([0.2126, 0.7152, 0.0722])


@pytest.fixture(scope="module")
def ic():
    return pytest.importorskip("imagecorruptions", reason="imagecorruptions is not installed "
                               "(pip install --no-deps imagecorruptions==1.1.2)")


@pytest.fixture(scope="module")
def axis_values(ic):
    """Every (corruption, severity)'s chart value, measured once for the module."""
    return {(n, s): sp.chart_axis_value(n, s) for n in sp.SPATIAL_CORRUPTIONS
            for s in sp.SEVERITIES}


def _image(seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (rng.random((48, 64, 3)) * 256).astype(np.uint8)


def test_seeded_corruption_is_deterministic_and_leaves_the_global_generator(ic):
    img = _image()
    np.random.seed(123)  # noqa: NPY002
    before = np.random.get_state()[1].copy()  # noqa: NPY002
    f = sp.SpatialCorruption("gaussian_noise", 2)
    a, b = f.for_image(139)(img), f.for_image(139)(img)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, f.for_image(285)(img))
    assert np.array_equal(np.random.get_state()[1], before)  # noqa: NPY002
    # the seed is the documented one, and the corruption the package's own
    seed = sp.corruption_seed("gaussian_noise", 2, 139)
    assert seed == int.from_bytes(
        __import__("hashlib").sha256(b"imagecorruptions:gaussian_noise:2:139").digest()[:4],
        "big")
    np.random.seed(seed)  # noqa: NPY002
    assert np.array_equal(a, ic.corrupt(img, severity=2, corruption_name="gaussian_noise"))


@pytest.mark.parametrize("name", ["defocus_blur", "shot_noise"])
def test_the_corruption_is_the_packages(ic, name):
    img = _image(5)
    for sev in sp.SEVERITIES:
        np.random.seed(9)  # noqa: NPY002
        want = ic.corrupt(img, severity=sev, corruption_name=name)
        assert np.array_equal(sp.apply_corruption(img, name, sev, seed=9), want), sev


def test_gaussian_blur_is_skimages_gaussian_of_the_packages_sigma(ic):
    from skimage.filters import gaussian

    img = _image(6)
    for sev, sigma in zip(sp.SEVERITIES, (1, 2, 3, 4, 6), strict=True):
        want = (np.clip(gaussian(img / 255.0, sigma=sigma, channel_axis=-1), 0, 1)
                * 255).astype(np.uint8)
        assert np.array_equal(sp.apply_corruption(img, "gaussian_blur", sev), want), sev


def test_bad_names_and_severities():
    with pytest.raises(Exception, match="fog: unknown"):
        sp.SpatialCorruption("fog", 1)
    with pytest.raises(Exception, match="severity 0"):
        sp.apply_corruption(_image(), "gaussian_blur", 0)


@pytest.mark.parametrize("name", sp.SPATIAL_CORRUPTIONS)
def test_the_chart_value_falls_with_severity(axis_values, name):
    """MTF50 falls with blur severity, SNR with noise severity."""
    xs = [axis_values[(name, s)].x for s in sp.SEVERITIES]
    assert all(x is not None for x in xs), xs
    assert all(a > b for a, b in zip(xs, xs[1:], strict=False)), xs
    v = axis_values[(name, 1)]
    assert v.property == sp.PROPERTY[name]
    if v.property == "noise":  # the mean of the seeded draws, its standard error
        assert len(v.draws) == sp.CHART_DRAWS and len(set(v.seeds)) == sp.CHART_DRAWS
        assert v.u == pytest.approx(np.std(v.draws, ddof=1) / np.sqrt(sp.CHART_DRAWS))


def _encoded_gaussian_edge_mtf50(sigma: float, bright: np.ndarray, dark: np.ndarray) -> float:
    """MTF50 (cy/px) of the luminance edge of ``bright`` against ``dark`` (encoded sRGB)
    blurred by a Gaussian of ``sigma`` px ON THE ENCODED VALUES, through the pixel aperture (a
    1 px box), then decoded to linear light: the closed-form edge (Gaussian ESF box-averaged:
    exact integrals of Phi) decoded, differentiated and Fourier transformed numerically. For
    bright = dark + small contrast it is the Gaussian's exp(-2 pi^2 sigma^2 f^2) sinc(f)."""
    dx = 1 / 64
    x = np.arange(-40, 40, dx)

    def int_phi(t: np.ndarray) -> np.ndarray:
        z = t / (np.sqrt(2) * sigma)
        return t * 0.5 * (1 + erf(z)) + sigma / np.sqrt(2 * np.pi) * np.exp(-z * z)

    esf = int_phi(x + 0.5) - int_phi(x - 0.5)
    enc = dark[None, :] + (bright - dark)[None, :] * esf[:, None]
    lum = np.asarray(cm.linearize_srgb(np.clip(enc, 0, 1))) @ WEIGHTS
    lsf = np.gradient(lum, dx)
    f = np.linspace(0, 0.7, 2801)
    mtf = np.abs(np.exp(-2j * np.pi * np.outer(f, x)) @ lsf)
    mtf /= mtf[0]
    i = int(np.argmax(mtf < 0.5))
    return float(f[i - 1] + (0.5 - mtf[i - 1]) * (f[i] - f[i - 1]) / (mtf[i] - mtf[i - 1]))


def test_gaussian_blur_mtf50_agrees_with_the_closed_form(axis_values):
    """The chart's MTF50 under imagecorruptions' gaussian_blur (sigma 1, 2 px) is that of a
    Gaussian edge blurred on the encoded values: the chart's sharpest edge pair is its white
    patch against the frame (linear 0.03; the measurement picks the largest contrast), decoded
    to linear light before the e-SFR. The decoding sharpens the edge's luminance (at sigma 1
    the linear-light Gaussian alone gives 0.180 cy/px, more than 10 % below the measured); the
    encoded closed form agrees within 3 % at sigma 1 and 6 % at sigma 2. At sigma >= 3 px the
    measurement reads above it (its region of interest across the edge is at most a fraction of
    the patch gap: the edge spread no longer fits), as for the tables' own gaussian-blur
    levels, whose axis the corruption is put on."""
    from fidelity.colour.charts import load_reference

    ref = load_reference("safecolor")
    white = np.asarray(ref.srgb)[list(ref.patch_names).index("white 9.5")]
    frame = np.full(3, float(np.asarray(cm.delinearize_srgb(np.array([0.03])))[0]))
    # the linear closed form at sigma 1: exp(-2 pi^2 f^2) sinc(f) = 0.5 at f = 0.180
    assert _encoded_gaussian_edge_mtf50(1.0, frame + 1e-3, frame) == pytest.approx(0.180,
                                                                                abs=1e-3)
    # the linear-light Gaussian alone is more than 10 % low at sigma 1 (the decoding)
    assert axis_values[("gaussian_blur", 1)].x > 1.10 * 0.180
    for sev, sigma, rel in ((1, 1.0, 0.03), (2, 2.0, 0.06)):
        want = _encoded_gaussian_edge_mtf50(sigma, white, frame)
        got = axis_values[("gaussian_blur", sev)].x
        assert got == pytest.approx(want, rel=rel), (sigma, got, want)


def _gaussian_noise_snr(codes: np.ndarray, c: float) -> float:
    """The closed-form luminance SNR of a flat patch of 8-bit ``codes`` (R, G, B) under
    imagecorruptions' gaussian_noise of scale ``c``: code k = floor(255 clip(codes/255 + N(0,
    c), 0, 1)) with its exact probabilities (normal CDF over the 256 bins, the clipped tails
    into codes 0 and 255), decoded to linear light; SNR = mean(Y) / sd(Y), Y = w . linear,
    the channels independent."""
    k = np.arange(256)
    g = np.asarray(cm.linearize_srgb(k / 255.0))
    means, variances = [], []
    for code in codes:
        x = code / 255.0
        upper = np.append(norm.cdf(((k[:-1] + 1) / 255.0 - x) / c), 1.0)
        lower = np.insert(norm.cdf((k[1:] / 255.0 - x) / c), 0, 0.0)
        p = upper - lower
        m = float((p * g).sum())
        means.append(m)
        variances.append(float((p * g * g).sum()) - m * m)
    return float(WEIGHTS @ np.array(means)) / float(np.sqrt((WEIGHTS ** 2) @ np.array(variances)))


def test_gaussian_noise_snr_agrees_with_the_closed_form(axis_values):
    """The chart's SNR at 18 % grey (luminance mu / sigma in linear light, the measurement's
    definition) under gaussian_noise agrees with the closed form of the grey patch's 8-bit
    codes within 2 % at every severity (the mean of the seeded draws; the closed form includes
    the clipping and the truncation to 8 bits)."""
    from fidelity.coco.degradations import encode_srgb8
    from fidelity.colour.charts import load_reference

    ref = load_reference("safecolor")
    grey = np.asarray(cm.linearize_srgb(ref.srgb))[list(ref.patch_names).index("neutral 5")]
    codes = encode_srgb8(grey[None, :])[0].astype(float)  # the calibration chart's paint
    for sev, c in zip(sp.SEVERITIES, sp.PARAMETERS["gaussian_noise"], strict=True):
        want = _gaussian_noise_snr(codes, c)
        v = axis_values[("gaussian_noise", sev)]
        assert v.x == pytest.approx(want, rel=0.02), (sev, v.x, want)


def _shot_noise_snr(codes: np.ndarray, c: float) -> float:
    """The closed-form luminance SNR of a flat patch of 8-bit ``codes`` under
    imagecorruptions' shot_noise of ``c``: n ~ Poisson(c codes/255), code floor(255 clip(n /
    c, 0, 1)), decoded; channels independent."""
    from scipy.stats import poisson

    means, variances = [], []
    for code in codes:
        lam = code / 255.0 * c
        n = np.arange(0, int(lam + 20 * np.sqrt(lam) + 50))
        p = poisson.pmf(n, lam)
        g = np.asarray(cm.linearize_srgb(np.floor(np.clip(n / float(c), 0, 1) * 255) / 255.0))
        m = float((p * g).sum())
        means.append(m)
        variances.append(float((p * g * g).sum()) - m * m)
    return float(WEIGHTS @ np.array(means)) / float(np.sqrt((WEIGHTS ** 2) @ np.array(variances)))


def test_shot_noise_snr_agrees_with_the_closed_form(axis_values):
    """As for gaussian_noise, with the Poisson distribution: within 2 % at every severity."""
    from fidelity.coco.degradations import encode_srgb8
    from fidelity.colour.charts import load_reference

    ref = load_reference("safecolor")
    grey = np.asarray(cm.linearize_srgb(ref.srgb))[list(ref.patch_names).index("neutral 5")]
    codes = encode_srgb8(grey[None, :])[0].astype(float)
    for sev, c in zip(sp.SEVERITIES, sp.PARAMETERS["shot_noise"], strict=True):
        want = _shot_noise_snr(codes, float(c))
        v = axis_values[("shot_noise", sev)]
        assert v.x == pytest.approx(want, rel=0.02), (sev, v.x, want)


# --------------------------------------------------------------------------------------------
# The results table and the CLI
# --------------------------------------------------------------------------------------------


def _results() -> cc.CocoCResults:
    return cc.CocoCResults.from_json(json.loads((ROOT / "reports/cococ/cococ.json").read_text()))


def _spatial_cell(name: str = "gaussian_blur", sev: int = 3, loss: float = 5.0) -> cc.SpatialCell:
    axis = sp.AxisValue(sp.PROPERTY[name], 0.08 if sp.PROPERTY[name] == "sharpness" else 2.0,
                        0.004, None, (0.08,), ())
    m = _results().cells[0].measured[0]
    return cc.SpatialCell(name, sev, sp.PARAMETERS[name][sev - 1], axis,
                          (replace(m, dmap_points=loss, dmap_points_se=1.0),),
                          cc.predict_spatial(axis))


def test_spatial_cells_round_trip_and_merge_keeps_the_colour_rows():
    shipped = _results()
    base = replace(shipped, spatial=(), meta={k: v for k, v in shipped.meta.items()
                                              if k != "spatial_run"})
    new = cc.CocoCResults((), base.chart, base.floor_delta_e,
                          {"spatial_run": {"models": ["x.onnx"], "images": "/a/val2017"}},
                          (_spatial_cell(),))
    merged = cc.merge_results(base, new)
    assert merged.cells == base.cells
    assert {k: v for k, v in merged.meta.items() if k != "spatial_run"} == base.meta
    assert merged.meta["spatial_run"]["models"] == ["x.onnx"]
    assert merged.spatial == new.spatial
    again = cc.CocoCResults.from_json(json.loads(json.dumps(merged.to_json())))
    assert again.to_json() == merged.to_json()
    assert merged.without_locations().meta["spatial_run"]["images"] == "val2017"
    # without spatial cells the JSON has no spatial key (the colour table as it was)
    assert "spatial_cells" not in base.to_json()
    # merged into the shipped table, one cell replaces its own and keeps the others
    both = cc.merge_results(shipped, new)
    assert len(both.spatial) == len(shipped.spatial)
    assert both.spatial_cell("gaussian_blur", 3) == new.spatial[0]
    assert both.spatial_cell("gaussian_blur", 2) == shipped.spatial_cell("gaussian_blur", 2)


def test_the_prediction_is_the_property_tables_and_bounds_are_counted():
    cell = _spatial_cell(loss=5.0)
    p = predict_property(load_property_table("sharpness"), 0.08, u_x=0.004, size="n")
    assert cell.prediction == p
    b = cell.bound(cell.measured[0].model)
    assert b is not None and b.classic_within is (5.0 <= p.loss)
    res = replace(_results(), spatial=(cell, _spatial_cell("shot_noise", 2, loss=1e3)))
    s = res.spatial_bounds()
    assert s.cells == 2 and s.classic_within == int(5.0 <= p.loss)


def test_the_report_has_the_noise_and_blur_table(tmp_path):
    from fidelity.report.cococ import SPATIAL_SECTION, cococ_document, write_cococ_report
    from fidelity.report.html import render_markdown

    cell = _spatial_cell()
    res = replace(_results(), spatial=(cell,))
    md = render_markdown(cococ_document(res))
    assert SPATIAL_SECTION in md
    p = cell.prediction
    assert p is not None
    row = [line for line in md.split("\n") if line.startswith("| gaussian_blur:3 |")]
    assert len(row) == 1 and "MTF50 0.0800 ± 0.0040" in row[0]
    assert f"{p.loss:.2f} ± {p.u_loss:.2f}" in row[0]
    written = write_cococ_report(res, tmp_path)
    assert (tmp_path / "cococ-loss-vs-mtf50.svg") in written
    assert not (tmp_path / "cococ-loss-vs-snr.svg").exists()


def test_coco_c_takes_the_new_names_and_refuses_unknown_ones(tmp_path):
    r = CliRunner().invoke(main, ["coco-c", "--corruptions", "gaussian_blur,fog",
                                  "--out", str(tmp_path)])
    lines = [x for x in r.output.split("\n") if x]
    assert r.exit_code == 2 and len(lines) == 1, r.output
    assert lines[0].startswith("fidelity: error: --corruptions: fog: unknown corruption")
    assert "gaussian_blur" in lines[0] and "shot_noise" in lines[0]
    r = CliRunner().invoke(main, ["coco-c", "--out", str(tmp_path), "--report-only",
                                  "--update"])
    assert r.exit_code == 2


@pytest.mark.parametrize("spec", ["gaussian_blur:6", "shot_noise:0", "gaussian_blur"])
def test_predict_coco_c_refuses_bad_severities(spec):
    r = CliRunner().invoke(main, ["predict", "--coco-c", spec])
    lines = [x for x in r.output.split("\n") if x]
    assert r.exit_code == 2 and len(lines) == 1 and lines[0].startswith("fidelity: error: ")


def test_predict_coco_c_answers_a_blur_on_the_mtf50_scale(ic, tmp_path):
    out = tmp_path / "a.json"
    r = CliRunner().invoke(main, ["predict", "--coco-c", "gaussian_blur:3", "--size", "n",
                                  "--json", str(out)])
    assert r.exit_code == 0, r.output
    v = sp.chart_axis_value("gaussian_blur", 3)
    p = predict_property(load_property_table("sharpness"), v.x, u_x=v.u, size="n")
    assert f"chart MTF50 {v.x:.4f} ± {v.u:.4f} cy/px" in r.output
    assert f"predicted ΔmAP: {p.loss:.2f} ± {p.u_loss:.2f} points" in r.output
    doc = json.loads(out.read_text())
    assert doc["axis"]["x"] == pytest.approx(v.x) and doc["prediction"]["loss"] == p.loss
    shipped = cc.load_coco_c()
    try:
        cell = shipped.spatial_cell("gaussian_blur", 3)
    except Exception:
        assert "measured: not in the COCO-C table" in r.output
        return
    for m in cell.measured:
        assert f"measured ΔmAP: {m.dmap_points:.2f} ± {m.dmap_points_se:.2f} points" in r.output
    assert len(doc["measured"]) == len(cell.measured)


def test_shipped_noise_and_blur_cells_are_what_the_code_computes(ic):
    """The shipped table's noise and blur cells: their chart values are what the chart gives
    now, their predictions what the property tables give now, and the report's JSON holds the
    same run."""
    shipped = cc.load_coco_c()
    report = _results()
    assert shipped.to_json() == report.without_locations().to_json()
    assert len(shipped.spatial) == len(sp.SPATIAL_CORRUPTIONS) * len(sp.SEVERITIES)
    for c in shipped.spatial:
        now = sp.chart_axis_value(c.corruption, c.severity)
        assert c.axis.x == pytest.approx(now.x, rel=1e-9)
        assert c.prediction == cc.predict_spatial(c.axis)
        assert c.measured, (c.corruption, c.severity)


def test_shipped_noise_and_blur_measurements_state_this_versions_detectors():
    """Every shipped noise or blur loss was measured with this version's detector
    preprocessing, its SE rule and the seeded corruption's store key."""
    from fidelity.coco.bootstrap import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED
    from fidelity.coco.detectors import PREPROCESSING

    res = cc.load_coco_c()
    current = {p.describe() for p in PREPROCESSING.values()}
    assert len(res.spatial) == len(sp.SPATIAL_CORRUPTIONS) * len(sp.SEVERITIES)
    for c in res.spatial:
        assert c.measured, (c.corruption, c.severity)
        for m in c.measured:
            assert m.mapping == sp.SpatialCorruption(c.corruption, c.severity).key
            assert m.settings.get("preprocess") in current, (m.model, m.mapping)
            assert m.settings.get("standard_error") == {
                "method": "larger", "draws": BOOTSTRAP_RESAMPLES, "seed": BOOTSTRAP_SEED}
            assert m.settings.get("threads") == 1
