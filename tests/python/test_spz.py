"""Niantic SPZ: hand-built version 2 files, the Python API, hostile files, and interoperability
with PlayCanvas's splat-transform 3.7.0 in both directions.

splat-transform 3.7 reads and writes SPZ without any axis change (its PLY axes, RDF, straight
into the file), while the SPZ specification and avsplat store RUB. So: our RUB file decoded by
splat-transform is our cloud turned 180 degrees about x; splat-transform's files are read here
with coordinate_system="rdf" and then agree value by value with its own decode.
"""
import gzip
import os
import struct

import numpy as np
import pytest

import avsplat

C0 = 0.28209479177387814
COLOR_SCALE = 0.15  # SPZ's DC colour scale
# RUB <-> RDF is diag(1, -1, -1): positions, quaternion (x, y, z) and the SH coefficients of
# bands 1..3 change sign by the parity of each basis function in y and z.
FLIP = np.array([1.0, -1.0, -1.0])
QUAT_SIGN = np.array([1.0, 1.0, -1.0, -1.0])  # w, x, y, z
SH_SIGN = np.array([1.0, -1, -1, 1, -1, 1, 1, -1, 1, -1, 1, -1, -1, 1, -1, 1])  # DC, then bands 1..3

# Half a quantisation step of each field (SPZ's reference quantisation, fractional bits 12).
BOUND = {
    "means": 0.5 / 4096 + 1e-5,
    "log_scales": 0.5 / 16 + 1e-6,
    "rotation_matrix": 4e-3,
    "opacities": 0.5 / 255 + 1e-6,
    "dc": 0.5 / 255 / COLOR_SCALE + 1e-6,
    "band1": 4.5 / 128 + 1e-6,
    "bands23": 8.5 / 128 + 1e-6,
}


def random_cloud(n, degree, seed):
    rng = np.random.default_rng(seed)
    k = (degree + 1) ** 2
    sh = rng.uniform(-0.9, 0.9, (n, k, 3))
    sh[:, 0, :] = rng.uniform(-3, 3, (n, 3))
    return avsplat.GaussianCloud(
        rng.uniform(-50, 50, (n, 3)),
        np.exp(rng.uniform(-6, 3, (n, 3))),
        rng.normal(size=(n, 4)),
        rng.uniform(0.01, 0.99, n),
        sh,
    )


def embedded_scene():
    pred = avsplat.simulate_predictions(views=6, width=64, height=48, seed=0)
    return avsplat.fuse_gaussians(pred.gaussians(), 0.05, policy="occupancy").cloud


def rotation_matrices(q):
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ],
        axis=1,
    )


def flipped(cloud):
    """The cloud's arrays after diag(1, -1, -1) (RDF <-> RUB), as plain float64 numpy."""
    k = cloud.sh_coeffs
    return {
        "means": cloud.means * FLIP,
        "scales": np.array(cloud.scales, np.float64),
        "rotations": cloud.rotations * QUAT_SIGN,
        "opacities": np.array(cloud.opacities, np.float64),
        "sh": cloud.sh * SH_SIGN[:k, None],
    }


def arrays(cloud):
    return {
        "means": np.array(cloud.means, np.float64),
        "scales": np.array(cloud.scales, np.float64),
        "rotations": np.array(cloud.rotations, np.float64),
        "opacities": np.array(cloud.opacities, np.float64),
        "sh": np.array(cloud.sh, np.float64),
    }


def canonical_xyz(q):
    """x, y, z of the unit quaternions (w, x, y, z) turned to w >= 0, as version 2 stores them."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return (q * np.where(q[:, :1] < 0, -1.0, 1.0))[:, 1:]


def assert_within_quantisation(got, want, version=4):
    """got, want: dicts of arrays (see arrays()); SPZ's quantisation bounds per field. Version 2
    stores x, y, z of the quaternion at 1/127.5 steps (w derived), so those are held to half a
    step h instead of the smallest-three bound on the rotation matrix, plus what the reader's
    renormalisation adds when the rounded x, y, z exceed unit length (w near 0): at most
    sqrt(3) h more."""
    assert np.abs(got["means"] - want["means"]).max() <= BOUND["means"]
    assert np.abs(np.log(got["scales"]) - np.log(want["scales"])).max() <= BOUND["log_scales"]
    if version == 2:
        assert np.abs(canonical_xyz(got["rotations"]) - canonical_xyz(want["rotations"])).max() <= (1 + 3 ** 0.5) * 0.5 / 127.5
    else:
        assert np.abs(rotation_matrices(got["rotations"]) - rotation_matrices(want["rotations"])).max() <= BOUND["rotation_matrix"]
    assert np.abs(got["opacities"] - want["opacities"]).max() <= BOUND["opacities"]
    err = np.abs(got["sh"] - want["sh"])
    assert err[:, 0].max() <= BOUND["dc"]
    if err.shape[1] > 1:
        assert err[:, 1:4].max() <= BOUND["band1"]
    if err.shape[1] > 4:
        assert err[:, 4:].max() <= BOUND["bands23"]


def assert_same_decode(got, want):
    """Two decodes of the same bytes: equal up to float32 rounding of the arithmetic.
    Positions (fixed point times a power of two) exactly; scales (exp of a log on the 1/16 grid)
    to 1e-6 relative; unit quaternions to 1e-6 (up to sign); opacity to 2e-6 (splat-transform
    writes the logit of byte/255 clamped to [1e-6, 1 - 1e-6]); DC to 1e-5 (float32 of
    (byte/255 - 0.5)/0.15); higher SH, (byte - 128)/128, exactly."""
    np.testing.assert_array_equal(got["means"], want["means"])
    np.testing.assert_allclose(got["scales"], want["scales"], rtol=1e-6)
    qa = got["rotations"] / np.linalg.norm(got["rotations"], axis=1, keepdims=True)
    qb = want["rotations"] / np.linalg.norm(want["rotations"], axis=1, keepdims=True)
    qb = qb * np.sign(np.sum(qa * qb, axis=1, keepdims=True))
    np.testing.assert_allclose(qa, qb, atol=1e-6)
    np.testing.assert_allclose(got["opacities"], want["opacities"], atol=2e-6)
    np.testing.assert_allclose(got["sh"][:, 0], want["sh"][:, 0], atol=1e-5)
    np.testing.assert_array_equal(got["sh"][:, 1:], want["sh"][:, 1:])


def v2_file(count, degree, flags, blocks):
    header = struct.pack("<IIIBBBB", 0x5053474E, 2, count, degree, 12, flags, 0)
    return gzip.compress(header + b"".join(blocks))


def test_reads_a_hand_built_version_2_file(tmp_path):
    # Two Gaussians of SH degree 1, RUB in the file.
    pos = struct.pack("<6i", 4096, -4096, 2048, -1, 0, 1 << 12)
    pos = b"".join(pos[4 * i : 4 * i + 3] for i in range(6))  # 24-bit little endian
    alphas = bytes([255, 0])
    colors = bytes([128, 255, 0, 38, 38, 38])
    scales = bytes([160, 160, 0, 96, 112, 128])
    rotations = bytes([0, 128, 128, 140, 100, 200])  # x, y, z; w >= 0 derived
    sh = bytes([64, 128, 192, 136, 120, 128, 128, 128, 255]) + bytes(range(100, 109))
    path = tmp_path / "v2.spz"
    path.write_bytes(v2_file(2, 1, 1, [pos, alphas, colors, scales, rotations, sh]))
    assert avsplat.read_spz_header(path) == {
        "version": 2, "count": 2, "sh_degree": 1, "fractional_bits": 12, "antialiased": True}

    c = avsplat.read_spz(path)
    assert c.antialiased and c.sh_degree == 1 and len(c) == 2
    np.testing.assert_array_equal(c.means, [[1, 1, -0.5], [-1 / 4096, 0, -1]])
    np.testing.assert_allclose(c.opacities, [1, 0])
    dc = (np.array([[128, 255, 0], [38, 38, 38]]) / 255 - 0.5) / COLOR_SCALE
    np.testing.assert_allclose(c.sh[:, 0], dc, rtol=1e-6)
    np.testing.assert_allclose(c.scales, np.exp(np.array([[160, 160, 0], [96, 112, 128]]) / 16 - 10), rtol=1e-6)
    xyz = np.array([[0, 128, 128], [140, 100, 200]]) / 127.5 - 1
    w = np.sqrt(np.maximum(0, 1 - (xyz**2).sum(1)))
    q = np.column_stack([w, xyz]) * QUAT_SIGN
    np.testing.assert_allclose(c.rotations, q / np.linalg.norm(q, axis=1, keepdims=True), atol=1e-7)
    rest = (np.frombuffer(sh, np.uint8).reshape(2, 3, 3) - 128.0) / 128
    np.testing.assert_array_equal(c.sh[:, 1:], rest * SH_SIGN[1:4, None])
    # The same bytes read as RDF: nothing changes sign.
    r = avsplat.read_spz(path, coordinate_system="rdf")
    np.testing.assert_array_equal(r.means, c.means * FLIP)
    np.testing.assert_array_equal(r.sh[:, 1:], rest)


def test_round_trip_keeps_antialiased_and_the_quantisation(tmp_path):
    cloud = random_cloud(300, 3, 1)
    cloud.antialiased = True
    for version in (2, 3, 4):
        path = tmp_path / f"rt{version}.spz"
        avsplat.write_spz(path, cloud, version=version)
        header = avsplat.read_spz_header(path)
        assert header["version"] == version and header["antialiased"] and header["count"] == 300
        back = avsplat.read_spz(path)
        assert back.antialiased
        assert_within_quantisation(arrays(back), arrays(cloud), version)
        # read_gaussians recognises the content whatever the name.
        other = tmp_path / f"renamed{version}.ply"
        other.write_bytes(path.read_bytes())
        np.testing.assert_array_equal(avsplat.read_gaussians(other).means, back.means)
    avsplat.write_gaussians(tmp_path / "g.spz", cloud)
    assert avsplat.read_spz_header(tmp_path / "g.spz")["version"] == 4
    assert avsplat.concatenate([cloud, cloud]).antialiased
    assert not avsplat.concatenate([cloud, random_cloud(2, 3, 2)]).antialiased


def test_hostile_files_raise_oserror_naming_the_file_and_field(tmp_path):
    # A gzip stream of 60 bytes whose header claims 4 billion Gaussians (231 GB): refused unread.
    claim = tmp_path / "claim.spz"
    claim.write_bytes(v2_file(0xFFFFFFFF, 3, 0, [bytes(24)]))
    with pytest.raises(OSError, match=r"claim\.spz: numPoints: 4294967295 Gaussians need \d+ bytes, more than"):
        avsplat.read_spz(claim)
    # A claim within deflate's ratio (10000 Gaussians): the stream ends early.
    short = tmp_path / "short.spz"
    short.write_bytes(v2_file(10000, 0, 0, [bytes(24)]))
    with pytest.raises(OSError, match=r"short\.spz: numPoints: the header claims 10000 Gaussians \(190016 bytes\), the gzip stream holds 40"):
        avsplat.read_spz(short)
    # A real bomb: 64 MiB of zeros gzipped to ~64 KiB under a header for one Gaussian.
    bomb = tmp_path / "bomb.spz"
    bomb.write_bytes(gzip.compress(struct.pack("<IIIBBBB", 0x5053474E, 2, 1, 0, 12, 0, 0) + bytes(64 << 20)))
    with pytest.raises(OSError, match=r"bomb\.spz: numPoints: the gzip stream holds more than the 35 bytes"):
        avsplat.read_spz(bomb)
    good = tmp_path / "good.spz"
    avsplat.write_spz(good, random_cloud(5, 0, 3), version=3)
    data = good.read_bytes()
    cut = tmp_path / "cut.spz"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(OSError, match=r"cut\.spz: gzip stream is truncated"):
        avsplat.read_spz(cut)
    with pytest.raises(OSError, match="version: 7"):
        bad = tmp_path / "v7.spz"
        bad.write_bytes(gzip.compress(struct.pack("<IIIBBBB", 0x5053474E, 7, 0, 0, 12, 0, 0)))
        avsplat.read_spz(bad)
    with pytest.raises(OSError, match="missing.spz"):
        avsplat.read_spz(tmp_path / "missing.spz")
    with pytest.raises(ValueError, match="coordinate_system: 'xyz' is not one of"):
        avsplat.read_spz(good, coordinate_system="xyz")
    for version in (1, 5):
        with pytest.raises(ValueError, match=f"version: {version} cannot be written \\(2, 3 and 4 can\\)"):
            avsplat.write_spz(tmp_path / "w.spz", random_cloud(2, 0, 4), version=version)
    with pytest.raises(OSError):
        avsplat.write_spz(tmp_path / "no_dir" / "w.spz", random_cloud(2, 0, 4))


CLOUDS = [("random", d) for d in range(4)] + [("scene", None)]


def make_cloud(kind, degree):
    return embedded_scene() if kind == "scene" else random_cloud(2000, degree, 10 + degree)


@pytest.mark.parametrize("version", [4, 3, 2])
@pytest.mark.parametrize("kind,degree", CLOUDS)
def test_splat_transform_decodes_our_files(tmp_path, splat_transform, version, kind, degree):
    """Our .spz -> splat-transform -> .ply: its decode is our cloud in RUB (it does not change
    axes), within SPZ's quantisation of what we wrote, and equal to our own decode."""
    cloud = make_cloud(kind, degree)
    cloud.antialiased = True
    ours = tmp_path / "ours.spz"
    avsplat.write_spz(ours, cloud, version=version)
    splat_transform(ours, tmp_path / "theirs.ply")
    theirs = avsplat.read_ply(tmp_path / "theirs.ply")
    assert len(theirs) == len(cloud) and theirs.sh_degree == cloud.sh_degree
    assert_within_quantisation(flipped(theirs), arrays(cloud), version)
    assert_same_decode(flipped(theirs), arrays(avsplat.read_spz(ours)))
    assert_same_decode(arrays(theirs), arrays(avsplat.read_spz(ours, coordinate_system="rdf")))
    # The antialiased flag reaches splat-transform: it tags the PLY as Mip-Splatting's model.
    assert b"SplatRenderMode: mip" in (tmp_path / "theirs.ply").read_bytes()[:4096]


@pytest.mark.parametrize("version", [4, 3])
@pytest.mark.parametrize("kind,degree", CLOUDS)
def test_we_decode_splat_transform_files_as_it_does(tmp_path, splat_transform, version, kind, degree):
    """PLY -> splat-transform -> .spz -> avsplat, value by value against splat-transform's own
    decode of the same .spz (tolerances in assert_same_decode)."""
    cloud = make_cloud(kind, degree)
    src = tmp_path / "src.ply"
    avsplat.write_ply(src, cloud)
    # Postshot's PLY comment sets splat-transform's antialiased model, hence the SPZ flag.
    raw = src.read_bytes()
    src.write_bytes(raw.replace(b"ply\n", b"ply\ncomment antialiased 1\n", 1))
    theirs = tmp_path / "theirs.spz"
    splat_transform("--spz-version", version, src, theirs)
    assert avsplat.read_spz_header(theirs)["version"] == version
    splat_transform(theirs, tmp_path / "decoded.ply")
    decoded = avsplat.read_ply(tmp_path / "decoded.ply")

    got = avsplat.read_spz(theirs, coordinate_system="rdf")
    assert got.antialiased
    assert_same_decode(arrays(got), arrays(decoded))
    assert_within_quantisation(arrays(got), arrays(cloud))
    # Read as the specification's RUB (the default), the same bytes are turned about x.
    assert_same_decode(flipped(avsplat.read_spz(theirs)), arrays(got))


def with_extension(v4_bytes, record):
    """A v4 file with `record` inserted between the header and the table of contents."""
    header = bytearray(v4_bytes[:32])
    header[14] |= 0x2  # has extensions
    header[16:20] = struct.pack("<I", 32 + len(record))
    return bytes(header) + record + v4_bytes[32:]


def test_v4_extension_records_name_the_axes_or_are_skipped(tmp_path):
    plain = tmp_path / "plain.spz"
    avsplat.write_spz(plain, random_cloud(20, 1, 6))
    rdf = avsplat.read_spz(plain, coordinate_system="rdf")
    # Adobe's coordinate-system record (type 0xADBE0003, value 6 = RDF) overrides the option.
    marked = tmp_path / "marked.spz"
    marked.write_bytes(with_extension(plain.read_bytes(), struct.pack("<III", 0xADBE0003, 4, 6)))
    np.testing.assert_array_equal(avsplat.read_spz(marked).means, rdf.means)
    np.testing.assert_array_equal(avsplat.read_spz(marked).sh, rdf.sh)
    # Another record (the safe-orbit camera, 12 bytes) is skipped.
    other = tmp_path / "other.spz"
    other.write_bytes(with_extension(plain.read_bytes(), struct.pack("<IIfff", 0xADBE0002, 12, 0.1, 0.5, 2.0)))
    np.testing.assert_array_equal(avsplat.read_spz(other).means, avsplat.read_spz(plain).means)
    # A rotated family (value 9, LFD) is refused; a record longer than its area too.
    rotated = tmp_path / "rotated.spz"
    rotated.write_bytes(with_extension(plain.read_bytes(), struct.pack("<III", 0xADBE0003, 4, 9)))
    with pytest.raises(OSError, match=r"rotated\.spz: extension\[0\]: coordinate system 9"):
        avsplat.read_spz(rotated)
    long = tmp_path / "long.spz"
    long.write_bytes(with_extension(plain.read_bytes(), struct.pack("<III", 0xADBE0003, 40, 6)))
    with pytest.raises(OSError, match=r"long\.spz: extension\[0\]: byteLength 40 runs past"):
        avsplat.read_spz(long)


@pytest.mark.parametrize("reader", [avsplat.read_spz, avsplat.read_spz_header])
def test_directories_fifos_devices_and_nul_paths_are_refused_at_once(tmp_path, reader):
    fifo = tmp_path / "pipe.spz"
    os.mkfifo(fifo)
    for path, message in ((tmp_path, "is a directory"), (fifo, "not a regular file"),
                          ("/dev/zero", "not a regular file")):
        with pytest.raises(OSError, match=message) as err:
            reader(str(path))
        assert str(path) in str(err.value)
    with pytest.raises(ValueError, match="NUL"):
        reader(str(tmp_path / "a") + "\0b.spz")
    # Recognising SPZ by content must not open the FIFO either.
    with pytest.raises(OSError, match="not a regular file"):
        avsplat.read_gaussians(str(fifo))


def test_writing_to_a_full_disk_fails_loudly_and_keeps_the_old_file(tmp_path):
    with pytest.raises(OSError, match="No space left on device"):
        avsplat.write_spz("/dev/full", random_cloud(100, 3, 8))
    path = tmp_path / "keep.spz"
    avsplat.write_spz(path, random_cloud(10, 0, 8))
    before = path.read_bytes()
    with pytest.raises(ValueError, match=r"GaussianCloud.means\[0\]"):
        avsplat.write_spz(path, avsplat.GaussianCloud(np.full((1, 3), 1e8), np.ones((1, 3)),
                                                      np.array([[1.0, 0, 0, 0]]), np.ones(1), np.zeros((1, 1, 3))))
    assert path.read_bytes() == before


def test_cli_convert_writes_and_reads_spz(tmp_path):
    """`avsplat convert` goes through read_gaussians/write_gaussians: .ply -> .spz -> .ply."""
    import subprocess

    build = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__))))
    exe = os.path.join(build, "apps", "avsplat")
    if not os.access(exe, os.X_OK):
        pytest.skip(f"no avsplat binary at {exe}")
    cloud = random_cloud(200, 2, 12)
    avsplat.write_ply(tmp_path / "in.ply", cloud)
    for cmd in (["convert", tmp_path / "in.ply", tmp_path / "mid.spz"],
                ["convert", tmp_path / "mid.spz", tmp_path / "out.ply"]):
        done = subprocess.run([exe, *map(str, cmd)], capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
    assert avsplat.read_spz_header(tmp_path / "mid.spz")["version"] == 4
    back = avsplat.read_ply(tmp_path / "out.ply")
    assert_within_quantisation(arrays(back), arrays(cloud))
    np.testing.assert_array_equal(back.means, avsplat.read_spz(tmp_path / "mid.spz").means)


def test_cli_convert_spz_version_writes_each_version(tmp_path):
    """`avsplat convert --spz-version 2|3|4` writes that version, read back within its
    quantisation; the option with any other output is a one-line usage error."""
    import subprocess

    build = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__))))
    exe = os.path.join(build, "apps", "avsplat")
    if not os.access(exe, os.X_OK):
        pytest.skip(f"no avsplat binary at {exe}")
    cloud = random_cloud(150, 3, 13)
    avsplat.write_ply(tmp_path / "in.ply", cloud)
    for version in (2, 3, 4):
        out = tmp_path / f"v{version}.spz"
        done = subprocess.run([exe, "convert", "--spz-version", str(version), str(tmp_path / "in.ply"), str(out)],
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
        assert avsplat.read_spz_header(out)["version"] == version
        assert_within_quantisation(arrays(avsplat.read_spz(out)), arrays(cloud), version)
    # v2 stores 3 rotation bytes per Gaussian, v3 4: the gzip payloads differ by exactly that.
    sizes = {v: len(gzip.decompress((tmp_path / f"v{v}.spz").read_bytes())) for v in (2, 3)}
    assert sizes[3] - sizes[2] == len(cloud)
    for bad, why in ((["--spz-version", "2", "in.ply", "out.ply"], "applies to .spz output only"),
                     (["--spz-version", "1", "in.ply", "out.spz"], "--spz-version")):
        done = subprocess.run([exe, "convert", *[str(tmp_path / a) if a.endswith(".ply") or a.endswith(".spz") else a
                                                 for a in bad]], capture_output=True, text=True, timeout=120)
        assert done.returncode != 0 and why in done.stderr, done.stderr
        assert not (tmp_path / "out.ply").exists() and not (tmp_path / "out.spz").exists()
