"""Curves fitted to unordered, noisy, branching point clouds.

Every check is against an independent reference: the TRUE curve the cloud was
drawn from (dense samples), and brute-force dense sampling of the fitted
curves for distances; never against the fitting code itself.
"""

import json
import warnings

import jax.numpy as jnp
import numpy as np
import pytest
from numpy.polynomial import polynomial as P
from scipy.spatial import cKDTree

import softplan_jax as sp
from softplan_jax.cli import main as cli_main

SIGMA = 0.005


def curve_samples(curve, n=4000):
    """Dense samples (n, 3) of a PolynomialCurve over its u_range (brute force)."""
    coeffs = np.asarray(curve.coeffs, dtype=float)
    u = np.linspace(*np.asarray(curve.u_range, dtype=float), n)
    return np.stack([P.polyval(u, coeffs[a]) for a in range(3)], axis=1)


def brute_distance(points, curves, n=20000):
    """Distance from each point to the nearest of ``curves`` by dense sampling."""
    dense = np.concatenate([curve_samples(c, n) for c in curves])
    return cKDTree(dense).query(points)[0]


def cloud(parts, sigma=SIGMA, seed=0):
    """A shuffled noisy cloud from parts [(fn, lo, hi, n)], with the true curves
    densely sampled over the parameter range the samples actually cover."""
    rng = np.random.default_rng(seed)
    pts, truth = [], []
    for fn, lo, hi, n in parts:
        u = rng.uniform(lo, hi, n)
        pts.append(fn(u) + sigma * rng.normal(size=(n, 3)))
        truth.append(fn(np.linspace(u.min(), u.max(), 4000)))
    pts = np.concatenate(pts)
    return pts[rng.permutation(len(pts))], truth


def two_way(fit, truth):
    """(max distance true -> fitted curves, max distance fitted curves -> true)."""
    fitted = np.concatenate([curve_samples(c) for c in fit.curves])
    true = np.concatenate(truth)
    return cKDTree(fitted).query(true)[0].max(), cKDTree(true).query(fitted)[0].max()


quadratic = lambda u: np.stack([1 + 0.2 * u, u, 0.5 - u + 0.3 * u**2], 1)  # the shuffled-cloud example below
helix = lambda t: np.stack([0.5 * np.cos(t), 0.5 * np.sin(t), 0.15 * t], 1)
sine = lambda u: np.stack([u, 0.3 * np.sin(3 * u), 0.2 * u**2], 1)
trunk = lambda u: np.stack([1 + 0 * u, 1 + 0 * u, u], 1)
branch1 = lambda u: np.stack([1 + u, 1 + 0.3 * u, 1 + 0.6 * u], 1)  # grows from (1, 1, 1)
branch2 = lambda u: np.stack([1 - 0.5 * u, 1 + u, 2 + 0.4 * u - 0.2 * u**2], 1)  # from (1, 1, 2)
wire_x = lambda u: np.stack([u, 0 * u, 1 + 0 * u], 1)
wire_y = lambda u: np.stack([0 * u, u, 1 + 0.1 * u**2], 1)  # crosses wire_x at (0, 0, 1)
wire_far = lambda u: np.stack([u, 0.3 + 0 * u, 1.2 + 0.1 * u], 1)  # parallel to wire_x, 0.36 away

CLOUDS = {
    "quadratic": ([(quadratic, -1, 1, 400)], 1),
    "helix arc": ([(helix, 0, 2 * np.pi, 600)], 1),
    "sine": ([(sine, -1.5, 1.5, 600)], 1),
    "trunk + 2 branches": ([(trunk, 0, 3, 600), (branch1, 0, 0.8, 200), (branch2, 0, 0.8, 200)], 3),
    "crossing wires": ([(wire_x, -1, 1, 400), (wire_y, -1, 1, 400)], 2),
    "separate wires": ([(wire_x, -1, 1, 300), (wire_far, -1, 1, 300)], 2),
}


# ----------------------------------------------------------------------------
# A noisy quadratic, shuffled: the ordered-only fit fails, fit_curve recovers it.


def test_shuffled_quadratic_fit_matches_the_ordered_fit():
    rng = np.random.default_rng(0)
    u = np.linspace(-1, 1, 400)
    pts = quadratic(u) + SIGMA * rng.normal(size=(400, 3))
    ordered = sp.clouds.fit_polynomial_curve(jnp.asarray(pts), 2)
    ordered_max = brute_distance(pts, [ordered]).max()
    assert ordered_max < 0.03  # about 0.018 in order
    shuffled = pts[rng.permutation(400)]
    # The ordered-only fit on shuffled points is wrong, and now says so.
    with pytest.warns(sp.clouds.FitWarning, match="ordered"):
        bad = sp.clouds.fit_polynomial_curve(jnp.asarray(shuffled), 2)
    assert brute_distance(shuffled, [bad]).max() > 0.5  # about 1.57
    fit = sp.clouds.fit_curve(shuffled)
    assert fit.degree == 2  # chosen by BIC
    assert fit.max_residual <= 1.05 * ordered_max
    assert fit.max_residual == pytest.approx(brute_distance(shuffled, [fit.curve]).max(), abs=1e-6)
    truth = quadratic(np.linspace(-1, 1, 4000))
    assert max(two_way(fit, [truth])) < 3 * SIGMA
    # ordered=False delegates to fit_curve
    c = sp.clouds.fit_polynomial_curve(jnp.asarray(shuffled), 2, ordered=False)
    np.testing.assert_allclose(c.coeffs, fit.curve.coeffs, atol=1e-9)


# ----------------------------------------------------------------------------
# Single and branching clouds, polynomial and not.


@pytest.mark.parametrize("name", list(CLOUDS))
def test_fit_curves_recovers_the_true_curves(name):
    parts, n_curves = CLOUDS[name]
    pts, truth = cloud(parts)
    with warnings.catch_warnings():
        warnings.simplefilter("error", sp.clouds.FitWarning)  # a good fit must not warn
        fit = sp.clouds.fit_curves(pts)
    assert len(fit.fits) == n_curves, [f.degree for f in fit.fits]
    true_to_fit, fit_to_true = two_way(fit, truth)
    # every part of every true curve is near a fitted curve, and no fitted piece is extraneous
    assert true_to_fit < 4 * SIGMA, true_to_fit / SIGMA
    assert fit_to_true < 4 * SIGMA, fit_to_true / SIGMA
    # residuals: independent brute force, and the noise estimate is sane
    brute = brute_distance(pts, fit.curves)
    np.testing.assert_allclose(fit.residuals, brute, atol=2e-4)
    assert fit.max_residual == pytest.approx(fit.residuals.max())
    assert fit.rms_residual == pytest.approx(np.sqrt(np.mean(fit.residuals**2)))
    assert 0.7 * SIGMA < fit.noise < 1.3 * SIGMA
    # every point is labelled with its nearest curve; per-curve residuals agree
    assert sorted(np.unique(fit.labels)) == list(range(n_curves))
    for k, f in enumerate(fit.fits):
        np.testing.assert_array_equal(np.sort(f.indices), np.nonzero(fit.labels == k)[0])
        np.testing.assert_allclose(f.residuals, fit.residuals[f.indices], atol=1e-9)
        np.testing.assert_allclose(f.curve.u_range, [-1.0, 1.0])


def test_single_fit_of_a_non_polynomial_curve():
    pts, truth = cloud([(helix, 0, 2 * np.pi, 600)], seed=3)
    fit = sp.clouds.fit_curve(pts)
    assert 3 <= fit.degree <= 8
    assert max(two_way(fit, truth)) < 4 * SIGMA


# ----------------------------------------------------------------------------
# Exact point-curve distance.


def test_curve_distance_matches_dense_sampling():
    rng = np.random.default_rng(5)
    for degree in (1, 2, 3, 5):
        coeffs = rng.normal(size=(3, degree + 1))
        curve = sp.PolynomialCurve(coeffs, (-1.0, 1.5))
        pts = rng.normal(size=(200, 3)) * 2
        dist, u = sp.clouds.curve_distance(curve, pts)
        brute = brute_distance(pts, [curve], n=200000)
        assert np.all(dist <= brute + 1e-12)  # a global minimum
        np.testing.assert_allclose(dist, brute, atol=1e-5)
        assert np.all((u >= -1.0) & (u <= 1.5))
        foot = np.stack([P.polyval(u, coeffs[a]) for a in range(3)], 1)
        np.testing.assert_allclose(np.linalg.norm(foot - pts, axis=1), dist, atol=1e-12)


# ----------------------------------------------------------------------------
# Fit quality as data: max_residual, warnings, inflation.


def test_outliers_warn_and_max_residual_raises():
    pts, _ = cloud([(quadratic, -1, 1, 400)])
    outliers = np.array([[3.0, 3.0, 3.0], [-2.0, 1.0, 0.0]])
    dirty = np.concatenate([pts, outliers])
    with pytest.warns(sp.clouds.FitWarning, match="poor fit"):
        fit = sp.clouds.fit_curves(dirty)
    assert fit.max_residual > 1.0
    with pytest.raises(ValueError, match="max_residual"):
        sp.clouds.fit_curves(dirty, max_residual=0.05, warn=False)
    with pytest.raises(ValueError, match="max_residual"):
        sp.clouds.fit_curve(pts, degree=1, max_residual=0.05, warn=False)  # a line through a parabola
    fit = sp.clouds.fit_curve(pts, max_residual=0.05)  # the right degree passes
    assert fit.max_residual < 0.05


def test_inflate_covers_every_raw_point():
    pts, _ = cloud(CLOUDS["trunk + 2 branches"][0], seed=2)
    fit = sp.clouds.fit_curves(pts, inflate=True, radius=0.01)
    for f in fit.fits:
        assert float(f.curve.radius) == pytest.approx(0.01 + f.max_residual)
    # every raw point lies inside (or on) some inflated tube: brute force
    dense = [curve_samples(c, 20000) for c in fit.curves]
    inside = np.zeros(len(pts), bool)
    for c, d in zip(fit.curves, dense, strict=True):
        inside |= cKDTree(d).query(pts)[0] <= float(c.radius) + 1e-4
    assert inside.all()


def test_float32_smoke():
    pts, truth = cloud([(quadratic, -1, 1, 300)])
    fit = sp.clouds.fit_curves(pts.astype(np.float32))
    assert fit.curves[0].coeffs.dtype == jnp.float32
    assert max(two_way(fit, truth)) < 4 * SIGMA
    q = sp.scenarios.default_start().astype(jnp.float32)
    cp = sp.closest_point(q, fit.curves[0])
    assert cp.distance.dtype == jnp.float32 and np.isfinite(float(cp.distance))


# ----------------------------------------------------------------------------
# Bad clouds.


@pytest.mark.parametrize(
    "points, match",
    [
        (np.zeros((0, 3)), "empty"),
        (np.ones((10, 2)), r"shape \(N, 3\)"),
        (np.ones((10, 4)), r"shape \(N, 3\)"),
        (np.ones((5, 3, 1)), r"shape \(N, 3\)"),
        (np.ones((20, 3)), "identical"),
        (np.array([[0.0, 0, 0], [1, np.nan, 0]] * 5), r"NaN.*rows 1, 3"),
        (np.array([[0.0, 0, 0], [np.inf, 0, 0]] * 5), "NaN or inf"),
        ([["a", "b", "c"]] * 5, "numbers"),
    ],
)
def test_bad_clouds_raise_clear_errors(points, match):
    for fn in (sp.clouds.fit_curve, sp.clouds.fit_curves):
        with pytest.raises(ValueError, match=match):
            fn(points)


def test_too_few_points_for_the_degree():
    pts = np.random.default_rng(0).normal(size=(7, 3))
    with pytest.raises(ValueError, match="degree 3 needs at least 8"):
        sp.clouds.fit_curve(pts, degree=3)
    with pytest.raises(ValueError, match="at least 4"):
        sp.clouds.fit_curves(pts[:3])
    for bad in (0, -1, 2.5, True):
        with pytest.raises(ValueError, match="degree"):
            sp.clouds.fit_curve(pts, degree=bad)
    with pytest.raises(ValueError, match="max_residual"):
        sp.clouds.fit_curve(pts, max_residual=-1.0)


def test_load_cloud_formats_and_errors(tmp_path):
    pts, _ = cloud([(quadratic, -1, 1, 50)])
    np.save(tmp_path / "c.npy", pts)
    np.savetxt(tmp_path / "c.csv", pts, delimiter=",", header="x,y,z", comments="")
    np.savetxt(tmp_path / "c.xyz", pts, header="scanned branch")  # '# scanned branch' comment line
    for name in ("c.npy", "c.csv", "c.xyz"):
        np.testing.assert_allclose(sp.clouds.load_cloud(tmp_path / name), pts, rtol=1e-15)
    (tmp_path / "empty.csv").write_text("")
    (tmp_path / "wide.xyz").write_text("1 2 3 4\n5 6 7 8\n")
    (tmp_path / "ragged.csv").write_text("1,2,3\n4,5\n")
    (tmp_path / "text.csv").write_text("1,2,3\n4,five,6\n")
    (tmp_path / "nan.xyz").write_text("1 2 3\nnan 2 3\n4 5 6\n")
    np.save(tmp_path / "flat.npy", np.arange(6.0))
    (tmp_path / "c.obj").write_text("v 1 2 3\n")
    (tmp_path / "truncated.ply").write_text("ply\n")
    (tmp_path / "faces.ply").write_text("ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\n"
                                        "end_header\n")
    (tmp_path / "no_z.pcd").write_text("VERSION 0.7\nFIELDS x y\nSIZE 4 4\nTYPE F F\nCOUNT 1 1\nWIDTH 1\nHEIGHT 1\n"
                                       "POINTS 1\nDATA ascii\n1 2\n")
    (tmp_path / "short.pcd").write_text("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 3\nHEIGHT 1\n"
                                        "POINTS 3\nDATA ascii\n1 2 3\n")
    (tmp_path / "bad_header.pcd").write_text("VERSION 0.7\nCOLOUR red\n")
    cases = {
        "empty.csv": "empty",
        "wide.xyz": r"shape \(N, 3\)",
        "ragged.csv": "line 2",
        "text.csv": "line 2: not numbers",
        "nan.xyz": "NaN",
        "flat.npy": r"shape \(N, 3\)",
        "c.obj": "unknown extension",
        "truncated.ply": "not a valid PLY file",
        "faces.ply": "no 'vertex' element",
        "no_z.pcd": "no z field",
        "short.pcd": "holds 1 points, the header says 3",
        "bad_header.pcd": "line 2: unknown PCD header entry 'COLOUR'",
        "missing.npy": "not found",
    }
    for name, match in cases.items():
        with pytest.raises(ValueError, match=match):
            sp.clouds.load_cloud(tmp_path / name)


def test_load_cloud_reads_ply_and_pcd_written_by_other_tools(tmp_path):
    """PLY written by plyfile (ASCII and binary, with a colour property and a face element
    beside the vertices) and PCD written by pypcd4 (ascii, binary and binary_compressed, with
    rgb and intensity fields beside x, y, z): load_cloud gives the points the tools were given.
    pypcd4 writes a binary_compressed file only when LZF shrinks the data, so the cloud is a
    trunk sampled on a regular grid (compressible)."""
    import plyfile  # a core dependency
    import pypcd4  # the dev extra's PCD writer

    pts, _ = cloud([(quadratic, -1, 1, 300)])
    vertex = np.zeros(len(pts), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("red", "u1")])
    vertex["x"], vertex["y"], vertex["z"] = pts.T
    face = np.array([([0, 1, 2],)], dtype=[("vertex_indices", "i4", (3,))])
    for text in (True, False):
        path = tmp_path / f"scan_{'ascii' if text else 'binary'}.ply"
        plyfile.PlyData([plyfile.PlyElement.describe(vertex, "vertex"), plyfile.PlyElement.describe(face, "face")],
                        text=text).write(str(path))
        np.testing.assert_array_equal(sp.clouds.load_cloud(path), pts)

    z = np.linspace(0.0, 3.0, 2000)
    trunk = np.stack([np.ones_like(z), np.ones_like(z), z], axis=1).astype(np.float32)
    fields = ("x", "y", "z", "rgb", "intensity")
    types = (np.float32, np.float32, np.float32, np.uint32, np.uint8)
    pc = pypcd4.PointCloud.from_points(np.column_stack([trunk, np.full(2000, 123456), np.full(2000, 7)]), fields,
                                       types)
    for encoding in ("ascii", "binary", "binary_compressed"):
        path = tmp_path / f"scan_{encoding}.pcd"
        pc.save(str(path), encoding=pypcd4.Encoding(encoding))
        assert f"DATA {encoding}\n".encode() in path.read_bytes()[:400]
        got = sp.clouds.load_cloud(path)
        if encoding == "ascii":  # written as text with 10 decimals
            np.testing.assert_allclose(got, trunk, rtol=0, atol=1e-9)
        else:
            np.testing.assert_array_equal(got, trunk.astype(np.float64))


def test_load_cloud_drops_the_empty_pixels_of_an_organized_pcd(tmp_path):
    """An organized cloud (WIDTH x HEIGHT) marks pixels without a measurement with NaN x, y, z:
    they are dropped with a warning that counts them; a partly NaN point is still an error.
    The file is written here byte for byte as the PCL format documents DATA binary."""
    pts = np.array([[0.1, 0.2, 1.0], [np.nan, np.nan, np.nan], [0.3, 0.1, 1.2], [0.5, 0.0, 1.4]], np.float32)
    header = ("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n"
              "COUNT 1 1 1\nWIDTH 2\nHEIGHT 2\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA binary\n")
    path = tmp_path / "organized.pcd"
    path.write_bytes(header.encode() + pts.astype("<f4").tobytes())
    with pytest.warns(UserWarning, match="dropped 1 of 4 points"):
        got = sp.clouds.load_cloud(path)
    np.testing.assert_array_equal(got, pts[[0, 2, 3]].astype(np.float64))
    pts[1] = [0.2, np.nan, 1.0]
    path.write_bytes(header.encode() + pts.astype("<f4").tobytes())
    with pytest.raises(ValueError, match="NaN"):
        sp.clouds.load_cloud(path)


def test_cli_fit_reads_a_ply_scan(tmp_path, capsys):
    """``softplan fit scan.ply``: the curves of the cloud that plyfile wrote; an existing --plot
    is refused without --force, and replaced with it (said on stderr)."""
    import plyfile

    pts, _ = cloud(CLOUDS["crossing wires"][0])
    vertex = np.zeros(len(pts), dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
    vertex["x"], vertex["y"], vertex["z"] = pts.T
    src = tmp_path / "scan.ply"
    plyfile.PlyData([plyfile.PlyElement.describe(vertex, "vertex")], text=False).write(str(src))
    fig = tmp_path / "scan.png"
    fig.write_bytes(b"mine")
    assert cli_main(["fit", str(src), "--plot", str(fig)]) == 2
    assert "--plot" in capsys.readouterr().err and fig.read_bytes() == b"mine"
    assert not (tmp_path / "scan.json").exists()
    assert cli_main(["fit", str(src), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["points"] == len(pts) and len(summary["curves"]) == 2
    assert cli_main(["fit", str(src), "--plot", str(fig), "--force"]) == 0
    err = capsys.readouterr().err
    assert f"overwrote {fig}" in err and fig.stat().st_size > 10_000


# ----------------------------------------------------------------------------
# Scenario files and the command line.


def test_fit_scenario_json_round_trip(tmp_path):
    pts, _ = cloud(CLOUDS["crossing wires"][0])
    fit = sp.clouds.fit_curves(pts)
    path = tmp_path / "wires.json"
    sp.clouds.save_fit_scenario(fit, path, goal=[0.5, 0.5, 2.0], metadata={"source": "test"})
    data = json.loads(path.read_text())
    assert data["metadata"]["fit"]["max_residual"] == pytest.approx(fit.max_residual)
    assert data["metadata"]["source"] == "test"
    assert [o["metadata"]["fit"]["degree"] for o in data["obstacles"]] == [f.degree for f in fit.fits]
    scen = sp.load_scenario(path)
    assert int(scen.curve_mask.sum()) == 2
    for k, f in enumerate(fit.fits):
        np.testing.assert_allclose(scen.curves.coeffs[k, :, : f.degree + 1], f.curve.coeffs, atol=1e-12)
    with pytest.raises(ValueError, match="exists"):
        sp.clouds.save_fit_scenario(fit, path, goal=[0.5, 0.5, 2.0])
    # metadata must be an object; anything inside it is accepted
    data["metadata"] = [1, 2]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(data))
    with pytest.raises(ValueError, match="metadata"):
        sp.load_scenario(bad)


def test_cli_fit_then_plan(tmp_path, capsys):
    pts, _ = cloud(CLOUDS["trunk + 2 branches"][0])
    src = tmp_path / "tree.csv"
    np.savetxt(src, pts, delimiter=",")
    out, fig = tmp_path / "tree.json", tmp_path / "tree.png"
    rc = cli_main(["fit", str(src), "--goal", "1.6", "0.4", "1.6", "--inflate", "--plot", str(fig), "--json"])
    assert rc == 0, capsys.readouterr().err
    summary = json.loads(capsys.readouterr().out)
    assert len(summary["curves"]) == 3 and summary["scenario"] == str(out)
    assert fig.stat().st_size > 10_000
    data = json.loads(out.read_text())
    assert data["metadata"]["source"]["inflate"] is True
    scen = sp.load_scenario(out)
    assert int(scen.curve_mask.sum()) == 3
    np.testing.assert_allclose(scen.goal, [1.6, 0.4, 1.6])
    result = sp.plan(scen, method="curve", max_steps=5)
    assert result.q.shape[1:] == (3, 3) and np.isfinite(result.min_clearance)
    # a second run refuses to overwrite without --force
    assert cli_main(["fit", str(src)]) == 2
    assert "exists" in capsys.readouterr().err


@pytest.mark.parametrize(
    "content, ext, match",
    [
        ("", ".csv", "empty"),
        ("1 2\n3 4\n5 6\n", ".xyz", r"shape \(N, 3\)"),
        ("1,2,3\n" * 10, ".csv", "identical"),
        ("1,2,3\n2,3,4\n", ".csv", "at least"),
        ("1,2,3\nnan,1,1\n" * 5, ".csv", "NaN"),
        ("1 2 3\n", ".txt", "npy, .csv, .xyz"),
    ],
)
def test_cli_fit_bad_clouds_exit_2(tmp_path, capsys, content, ext, match):
    src = tmp_path / f"cloud{ext}"
    src.write_text(content)
    assert cli_main(["fit", str(src)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("softplan: error:") and len(err.strip().splitlines()) == 1
    assert pytest.importorskip("re").search(match, err), err
    assert not (tmp_path / "cloud.json").exists()


def test_cli_fit_max_residual_exit_2(tmp_path, capsys):
    pts, _ = cloud([(quadratic, -1, 1, 200)])
    src = tmp_path / "c.npy"
    np.save(src, pts)
    assert cli_main(["fit", str(src), "--degree", "1", "--max-residual", "0.05", "--single"]) == 2
    assert "max_residual" in capsys.readouterr().err
