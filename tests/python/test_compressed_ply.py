"""PlayCanvas compressed PLY against PlayCanvas's splat-transform 3.7.0, in both directions, and
format detection. Tolerances are stated per field below; "step" is one quantisation step of
the field in its chunk."""

import numpy as np
import pytest

import avsplat

C0 = 0.28209479177387814


def random_cloud(n, degree, seed):
    rng = np.random.default_rng(seed)
    k = (degree + 1) ** 2
    means = rng.normal(size=(n, 3)) * np.array([2.0, 1.0, 3.0])
    scales = np.exp(rng.uniform(-6, 0, (n, 3)))
    quats = rng.normal(size=(n, 4))
    opac = rng.uniform(0.01, 0.99, n)
    sh = rng.normal(size=(n, k, 3)) * np.where(np.arange(k) == 0, 1.0, 0.4)[None, :, None]
    return avsplat.GaussianCloud(means, scales, quats, opac, sh)


def scene_cloud():
    """The embedded default scene, fused from a few simulated views (SH degree of the samples)."""
    pred = avsplat.simulate_predictions(views=8, width=64, height=48, seed=0)
    return avsplat.fuse_gaussians(pred.gaussians(), 0.03).cloud


CLOUDS = [pytest.param(d, id=f"sh{d}") for d in range(4)] + [pytest.param("scene", id="scene")]


def make(which):
    return scene_cloud() if which == "scene" else random_cloud(1000, which, 100 + which)


def unit_sign(q):
    """Unit quaternions with the sign fixed (largest |component| positive)."""
    q = np.asarray(q, np.float64)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    big = np.take_along_axis(q, np.abs(q).argmax(axis=1)[:, None], axis=1)
    return q * np.sign(big)


def chunk_steps(values, bits):
    """Per-row quantisation step of `values` (N, ...) over its chunk of 256 rows."""
    n = len(values)
    steps = np.empty_like(values, dtype=np.float64)
    for first in range(0, n, 256):
        v = values[first:first + 256].astype(np.float64)
        steps[first:first + 256] = (v.max(axis=0) - v.min(axis=0)) / (2 ** np.asarray(bits) - 1)
    return steps


def assert_decodes_agree(ours, theirs):
    """avsplat's decode against splat-transform's decode (its PLY) of the same compressed file.
    Both compute min + (max - min) t in double and round to float32; splat-transform stores
    scale and opacity as float32 log / logit, so those carry one more float32 rounding."""
    assert len(ours) == len(theirs) and ours.sh_degree == theirs.sh_degree
    np.testing.assert_allclose(ours.means, theirs.means, rtol=0, atol=1e-6 * (1 + np.abs(ours.means).max()))
    np.testing.assert_allclose(ours.scales, theirs.scales, rtol=2e-6)        # exp of a float32 log
    np.testing.assert_allclose(ours.opacities, theirs.opacities, atol=2e-7)  # sigmoid of a float32 logit
    np.testing.assert_allclose(ours.rotations, theirs.rotations, atol=1e-7)  # same decode, same sign
    np.testing.assert_allclose(ours.sh, theirs.sh, atol=2e-6)                # dc: (c - 0.5) / C0; rest exact


@pytest.mark.parametrize("which", CLOUDS)
def test_our_file_reads_in_splat_transform(tmp_path, splat_transform, which):
    cloud = make(which)
    ours = tmp_path / "ours.compressed.ply"
    avsplat.write_compressed_ply(ours, cloud, morton_order=False)
    splat_transform(ours, tmp_path / "st.ply")
    theirs = avsplat.read_ply(tmp_path / "st.ply")
    # Value by value, splat-transform reads what we read.
    assert_decodes_agree(avsplat.read_compressed_ply(ours), theirs)
    # And both are what we wrote, within the quantisation (order kept: morton_order=False).
    n = len(cloud)
    step = chunk_steps(cloud.means, [11, 10, 11])
    assert np.all(np.abs(theirs.means - cloud.means) <= step / 2 + 1e-6 * (1 + np.abs(cloud.means)))
    log_step = chunk_steps(np.log(cloud.scales.astype(np.float64)), [11, 10, 11])
    assert np.all(np.abs(np.log(theirs.scales) - np.log(cloud.scales)) <= log_step / 2 + 1e-5)
    colour = 0.5 + C0 * cloud.sh[:, 0, :].astype(np.float64)
    col_step = chunk_steps(colour, [8, 8, 8])
    got = 0.5 + C0 * theirs.sh[:, 0, :].astype(np.float64)
    assert np.all(np.abs(got - colour) <= col_step / 2 + 1e-6)
    assert np.abs(theirs.opacities - cloud.opacities).max() <= 0.5 / 255 + 1e-6
    if cloud.sh_degree > 0:
        assert np.abs(theirs.sh[:, 1:] - np.clip(cloud.sh[:, 1:], -4, 4)).max() <= 8 / 256 + 1e-6
    dots = np.abs(np.sum(unit_sign(theirs.rotations) * unit_sign(cloud.rotations), axis=1))
    assert dots.min() > 1 - 4e-6  # within about 0.33 degrees
    assert n == len(theirs)


@pytest.mark.parametrize("which", CLOUDS)
def test_splat_transform_file_reads_in_avsplat(tmp_path, splat_transform, which):
    cloud = make(which)
    avsplat.write_ply(tmp_path / "in.ply", cloud)
    splat_transform(tmp_path / "in.ply", tmp_path / "st.compressed.ply")
    splat_transform(tmp_path / "st.compressed.ply", tmp_path / "st_decoded.ply")
    info = avsplat.detect_gaussian_format(tmp_path / "st.compressed.ply")
    assert info.format == "compressed_ply" and info.version.startswith("2")
    ours = avsplat.read_gaussians(tmp_path / "st.compressed.ply")
    assert_decodes_agree(ours, avsplat.read_ply(tmp_path / "st_decoded.ply"))

    # Our writer makes the same file: the same Morton order, the same bounds and the same packed
    # words; opacity may differ by one step where splat-transform's float32 logit rounds across
    # a half step. Only the header's comment line differs.
    avsplat.write_compressed_ply(tmp_path / "ours.compressed.ply", cloud)
    st = avsplat.read_ply_data(tmp_path / "st.compressed.ply")
    mine = avsplat.read_ply_data(tmp_path / "ours.compressed.ply")
    assert list(st) == list(mine)
    for element in st:
        assert list(st[element]) == list(mine[element]), element
        for prop in st[element]:
            a, b = st[element][prop], mine[element][prop]
            if prop == "packed_color":
                np.testing.assert_array_equal(a.astype(np.uint32) >> 8, b.astype(np.uint32) >> 8)
                assert np.abs((a.astype(np.int64) & 255) - (b.astype(np.int64) & 255)).max() <= 1
            else:
                np.testing.assert_array_equal(a, b, err_msg=f"{element}.{prop}")


def test_morton_order_is_a_permutation_and_written_order(tmp_path):
    cloud = random_cloud(3000, 1, 1)
    order = avsplat.morton_order(cloud)
    assert order.dtype == np.int64 and np.array_equal(np.sort(order), np.arange(3000))
    avsplat.write_compressed_ply(tmp_path / "m.compressed.ply", cloud)
    back = avsplat.read_compressed_ply(tmp_path / "m.compressed.ply")
    # Gaussian i of the file is cloud[order[i]] (within the quantisation of the means).
    assert np.abs(back.means - cloud.means[order]).max() < 0.05


def test_detection_dispatch_and_errors(tmp_path):
    cloud = random_cloud(10, 2, 3)
    avsplat.write_gaussians(tmp_path / "a.compressed.ply", cloud)
    avsplat.write_gaussians(tmp_path / "a.ply", cloud)
    avsplat.write_gaussians(tmp_path / "a.splat", cloud)
    got = {p: avsplat.detect_gaussian_format(tmp_path / p) for p in ("a.compressed.ply", "a.ply", "a.splat")}
    assert got["a.compressed.ply"].format == "compressed_ply"
    assert got["a.ply"].format == "ply" and got["a.ply"].version == "binary_little_endian 1.0"
    assert got["a.splat"].format == "splat" and got["a.splat"].name == ".splat"
    assert "compressed_ply" in repr(got["a.compressed.ply"])
    # The content decides, not the name.
    (tmp_path / "b.splat").write_bytes((tmp_path / "a.compressed.ply").read_bytes())
    assert avsplat.read_gaussians(tmp_path / "b.splat").sh_degree == 2
    assert len(avsplat.read_ply(tmp_path / "b.splat")) == 10
    (tmp_path / "c.bin").write_bytes(b"\x1f\x8b\x08\x00rest")
    assert avsplat.detect_gaussian_format(tmp_path / "c.bin").format == "spz"
    (tmp_path / "d.bin").write_bytes(b"hello")
    with pytest.raises(OSError, match=r"d\.bin: not a Gaussian file"):
        avsplat.read_gaussians(tmp_path / "d.bin")
    with pytest.raises(OSError, match="unsupported extension '.obj'"):
        avsplat.write_gaussians(tmp_path / "a.obj", cloud)
    bad = (tmp_path / "a.compressed.ply").read_bytes().replace(b"element chunk 1", b"element chunk 3")
    (tmp_path / "bad.ply").write_bytes(bad)
    with pytest.raises(OSError, match=r"bad\.ply: chunk element has 3 rows"):
        avsplat.read_compressed_ply(tmp_path / "bad.ply")
    with pytest.raises(ValueError, match="GaussianCloud"):
        broken = random_cloud(3, 0, 1)
        broken.scales[0, 0] = -1
        avsplat.write_compressed_ply(tmp_path / "x.compressed.ply", broken)


def cli(*args):
    import os
    import subprocess
    exe = os.path.join(os.path.dirname(avsplat.__file__), "..", "..", "apps", "avsplat")
    return subprocess.run([exe, *map(str, args)], capture_output=True, text=True)


def test_cli_info_and_convert(tmp_path):
    cloud = random_cloud(600, 3, 8)
    avsplat.write_ply(tmp_path / "in.ply", cloud)
    r = cli("convert", tmp_path / "in.ply", tmp_path / "out.compressed.ply")
    assert r.returncode == 0, r.stderr
    avsplat.write_compressed_ply(tmp_path / "py.compressed.ply", avsplat.read_ply(tmp_path / "in.ply"))
    assert (tmp_path / "out.compressed.ply").read_bytes() == (tmp_path / "py.compressed.ply").read_bytes()
    r = cli("info", tmp_path / "out.compressed.ply")
    assert r.returncode == 0 and "format         compressed PLY, version 2 (chunk colour bounds)" in r.stdout
    assert "gaussians      600" in r.stdout
    r = cli("info", tmp_path / "in.ply")
    assert "format         3DGS PLY, version binary_little_endian 1.0" in r.stdout
    # --axes, --scale and --translate: the same as avsplat.transform.
    r = cli("convert", tmp_path / "in.ply", tmp_path / "moved.ply", "--axes", "RUB:RDF", "--scale", "2",
            "--translate", "1,2,3")
    assert r.returncode == 0, r.stderr
    expect = avsplat.transform(avsplat.read_ply(tmp_path / "in.ply"), np.diag([1.0, -1.0, -1.0]), [1, 2, 3], 2.0)
    got = avsplat.read_ply(tmp_path / "moved.ply")
    for f in ("means", "rotations", "sh"):
        np.testing.assert_array_equal(getattr(got, f), getattr(expect, f), err_msg=f)
    np.testing.assert_allclose(got.scales, expect.scales, rtol=3e-7)  # through the file's float32 log
    r = cli("convert", tmp_path / "in.ply", tmp_path / "x.ply", "--rotate", "1,2")
    assert r.returncode != 0 and "--rotate" in r.stderr
    r = cli("convert", tmp_path / "in.ply", tmp_path / "x.ply", "--axes", "RUX:RDF")
    assert r.returncode != 0 and "RUX" in r.stderr
    assert not (tmp_path / "x.ply").exists()


def test_damaged_file_named_ply_is_not_guessed_to_be_splat(tmp_path):
    # 64 bytes would make two .splat records; a name that claims PLY is reported as a bad PLY.
    (tmp_path / "zeros.ply").write_bytes(bytes(64))
    with pytest.raises(OSError, match=r'zeros\.ply: not a PLY file: it does not start with "ply"'):
        avsplat.read_gaussians(tmp_path / "zeros.ply")
    (tmp_path / "renamed.bin").write_bytes(bytes(64))  # any other name: read as .splat records
    assert avsplat.detect_gaussian_format(tmp_path / "renamed.bin").format == "splat"


def test_big_endian_and_extra_elements_read_the_same(tmp_path):
    """The format is little endian in practice; a big-endian file (every chunk float and vertex
    word byte-swapped) and an unknown element before the chunk read the same."""
    cloud = random_cloud(300, 1, 4)
    avsplat.write_compressed_ply(tmp_path / "le.compressed.ply", cloud)
    head, body = (tmp_path / "le.compressed.ply").read_bytes().split(b"end_header\n", 1)
    words = (2 * 18 + 300 * 4) * 4  # chunk floats and vertex words; the sh bytes follow
    swapped = np.frombuffer(body[:words], "<u4").astype(">u4").tobytes() + body[words:]
    be_head = head.replace(b"binary_little_endian", b"binary_big_endian")
    be_head = be_head.replace(b"element chunk", b"element camera 2\nproperty short id\nelement chunk")
    (tmp_path / "be.ply").write_bytes(be_head + b"end_header\n" + b"\x00\x01\x00\x02" + swapped)
    le, be = avsplat.read_compressed_ply(tmp_path / "le.compressed.ply"), avsplat.read_gaussians(tmp_path / "be.ply")
    for f in ("means", "scales", "rotations", "opacities", "sh"):
        np.testing.assert_array_equal(getattr(be, f), getattr(le, f), err_msg=f)


def test_morton_order_over_rows_is_the_order_of_the_selected_rows():
    rng = np.random.default_rng(3)
    n = 2000
    cloud = avsplat.GaussianCloud(rng.uniform(-1, 1, (n, 3)).astype(np.float32), np.full((n, 3), 0.01, np.float32),
                                  np.tile(np.float32([1, 0, 0, 0]), (n, 1)), np.full(n, 0.5, np.float32),
                                  np.zeros((n, 1, 3), np.float32))
    rows = rng.permutation(n)[:1500]
    got = avsplat.morton_order(cloud, rows)
    assert got.dtype == np.int64
    assert np.array_equal(got, rows[avsplat.morton_order(cloud.select(rows))])
    assert np.array_equal(avsplat.morton_order(cloud, np.arange(n)), avsplat.morton_order(cloud))
    with pytest.raises(IndexError, match=r"rows\[1\] = 2000"):
        avsplat.morton_order(cloud, [0, 2000])
    with pytest.raises(IndexError, match="negative"):
        avsplat.morton_order(cloud, [0, -1])
    with pytest.raises(ValueError, match="1-D"):
        avsplat.morton_order(cloud, np.zeros((2, 2), np.int64))
