"""avsplat.read_ply / write_ply against Open3D's own PLY reader and writer and numpy."""

import pathlib

import numpy as np
import pytest

import avsplat

o3d = pytest.importorskip("open3d")


def random_cloud(n, degree, seed, confidence=True, extras=("label",)):
    rng = np.random.default_rng(seed)
    k = (degree + 1) ** 2
    cloud = avsplat.GaussianCloud(
        means=rng.normal(0.0, 10.0, (n, 3)),
        scales=np.exp(rng.uniform(np.log(1e-6), np.log(1e3), (n, 3))),
        rotations=rng.normal(size=(n, 4)),
        opacities=rng.uniform(1e-4, 1.0, n),
        sh=rng.normal(size=(n, k, 3)),
        confidence=rng.normal(size=n) if confidence else None,
    )
    for name in extras:
        cloud.set_extra(name, rng.normal(0.0, 100.0, n))
    return cloud


def ulps(a, b):
    """Distance in float32 units in the last place (non-negative inputs)."""
    a = np.asarray(a, np.float32).view(np.int32).astype(np.int64)
    b = np.asarray(b, np.float32).view(np.int32).astype(np.int64)
    return np.abs(a - b)


def same_bits(a, b):
    a, b = np.asarray(a, np.float32), np.asarray(b, np.float32)
    return a.shape == b.shape and np.array_equal(a.view(np.uint32), b.view(np.uint32))


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_open3d_reads_the_written_layout(tmp_path, degree):
    cloud = random_cloud(200, degree, seed=degree)
    path = tmp_path / "cloud.ply"
    avsplat.write_ply(path, cloud)
    pc = o3d.t.io.read_point_cloud(str(path))
    # Open3D 0.16 gives x y z as "positions", nx ny nz as "normals" and every other vertex
    # property as its own (N, 1) attribute under the property's name.
    attr = {name: pc.point[name].numpy() for name in pc.point}
    k = (degree + 1) ** 2
    expected = {"positions", "normals", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "confidence", "label"}
    expected |= {f"scale_{a}" for a in range(3)} | {f"rot_{a}" for a in range(4)}
    expected |= {f"f_rest_{i}" for i in range(3 * (k - 1))}
    assert set(attr) == expected

    assert same_bits(attr["positions"], cloud.means)
    assert np.all(attr["normals"] == 0.0)
    sh = cloud.sh
    for c in range(3):
        assert same_bits(attr[f"f_dc_{c}"][:, 0], sh[:, 0, c])
        # Channel-major: f_rest_{c*(K-1)+j} is coefficient j+1 of channel c.
        for j in range(k - 1):
            assert same_bits(attr[f"f_rest_{c * (k - 1) + j}"][:, 0], sh[:, j + 1, c])
    for a in range(4):
        assert same_bits(attr[f"rot_{a}"][:, 0], cloud.rotations[:, a])
    assert same_bits(attr["confidence"][:, 0], cloud.confidence)
    assert same_bits(attr["label"][:, 0], cloud.extras["label"])

    # On disk: logit opacity and log scales, computed in float64 and rounded once.
    p = cloud.opacities.astype(np.float64)
    logit = (np.log(p) - np.log1p(-p)).astype(np.float32)
    assert ulps(np.abs(attr["opacity"][:, 0]), np.abs(logit)).max() <= 1
    np.testing.assert_allclose(attr["opacity"][:, 0], np.log(p / (1.0 - p)), rtol=1e-6, atol=1e-6)
    for a in range(3):
        log_s = np.log(cloud.scales[:, a].astype(np.float64))
        assert ulps(np.abs(attr[f"scale_{a}"][:, 0]), np.abs(log_s.astype(np.float32))).max() <= 1
        np.testing.assert_allclose(attr[f"scale_{a}"][:, 0], log_s, rtol=1e-6, atol=1e-6)


def ply_columns(path):
    """A reference reader for float-only vertex data: {property name: float32 column}."""
    data = pathlib.Path(path).read_bytes()
    head, body = data.split(b"end_header\n", 1)
    lines = head.decode().splitlines()
    fmt = next(line.split()[1] for line in lines if line.startswith("format"))
    names = [line.split()[2] for line in lines if line.startswith("property float")]
    assert len(names) == sum(line.startswith("property") for line in lines)
    if fmt == "ascii":
        table = np.loadtxt(body.decode().splitlines(), dtype=np.float64, ndmin=2).astype(np.float32)
    else:
        assert fmt == "binary_little_endian"
        table = np.frombuffer(body, dtype="<f4").reshape(-1, len(names))
    return {name: table[:, k] for k, name in enumerate(names)}


def test_reads_files_written_by_open3d(tmp_path):
    # Open3D writes the attributes in its own (hash) order: real shuffled-property files, binary
    # and ASCII (6 significant digits).
    rng = np.random.default_rng(3)
    n = 50
    pc = o3d.t.geometry.PointCloud()
    pc.point.positions = o3d.core.Tensor(rng.normal(size=(n, 3)).astype(np.float32))
    names = ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    names += [f"f_dc_{c}" for c in range(3)] + [f"f_rest_{i}" for i in range(9)]  # degree 1
    for name in names:
        scale = 3.0 if name == "opacity" else 1.0
        values = rng.normal(0.0, scale, (n, 1)) - (4.0 if name.startswith("scale") else 0.0)
        pc.point[name] = o3d.core.Tensor(values.astype(np.float32))
    for ascii_ in (False, True):
        path = tmp_path / f"open3d_{'ascii' if ascii_ else 'binary'}.ply"
        assert o3d.t.io.write_point_cloud(str(path), pc, write_ascii=ascii_)
        col = ply_columns(path)
        cloud = avsplat.read_ply(path)
        assert len(cloud) == n and cloud.sh_degree == 1
        assert same_bits(cloud.means, np.stack([col["x"], col["y"], col["z"]], axis=1))
        for a in range(4):
            assert same_bits(cloud.rotations[:, a], col[f"rot_{a}"])
        for c in range(3):
            assert same_bits(cloud.sh[:, 0, c], col[f"f_dc_{c}"])
            for j in range(3):
                assert same_bits(cloud.sh[:, j + 1, c], col[f"f_rest_{c * 3 + j}"])
        # Decoded in float64 and rounded once (numpy's exp may differ in the last double bit).
        logit = col["opacity"].astype(np.float64)
        assert ulps(cloud.opacities, 1.0 / (1.0 + np.exp(-logit))).max() <= 1
        for a in range(3):
            assert ulps(cloud.scales[:, a], np.exp(col[f"scale_{a}"].astype(np.float64))).max() <= 1
        assert cloud.confidence is None and cloud.extras == {}


@pytest.mark.parametrize("degree", [0, 3])
def test_round_trip(tmp_path, degree):
    cloud = random_cloud(500, degree, seed=10 + degree, extras=("label", "weight"))
    cloud.opacities[:2] = [0.0, 1.0]
    path = tmp_path / "rt.ply"
    avsplat.write_ply(str(path), cloud)
    back = avsplat.read_ply(path)
    assert repr(back) == repr(cloud)
    for name in ("means", "rotations", "sh", "confidence"):
        assert same_bits(getattr(back, name), getattr(cloud, name)), name
    assert list(back.extras) == ["label", "weight"]
    for name, values in cloud.extras.items():
        assert same_bits(back.extras[name], values), name
    assert back.opacities[0] == 0.0 and back.opacities[1] == 1.0
    # float32 logit / log on disk: within 8 ulp (bit-exact where float32 has the resolution).
    assert ulps(back.opacities, cloud.opacities).max() <= 8
    assert ulps(back.scales, cloud.scales).max() <= 8
    mid = (cloud.scales > np.exp(-1.0)) & (cloud.scales < np.exp(1.0))
    assert mid.any() and np.all(back.scales[mid] == cloud.scales[mid])


def test_read_errors_raise_oserror_naming_the_file(tmp_path):
    missing = tmp_path / "missing.ply"
    with pytest.raises(OSError, match="missing.ply.*cannot open"):
        avsplat.read_ply(missing)

    text = tmp_path / "text.ply"
    text.write_text("hello\n")
    with pytest.raises(avsplat.IOError, match="text.ply.*not a PLY file"):
        avsplat.read_ply(str(text))

    good = tmp_path / "good.ply"
    avsplat.write_ply(good, random_cloud(10, 1, seed=1))
    data = good.read_bytes()
    cut = tmp_path / "cut.ply"
    cut.write_bytes(data[:-7])
    with pytest.raises(OSError, match="cut.ply.*truncated"):
        avsplat.read_ply(cut)

    no_scale = tmp_path / "no_scale.ply"
    no_scale.write_bytes(data.replace(b"property float scale_1\n", b"property float other_1\n"))
    with pytest.raises(OSError, match='no_scale.ply.*no "scale_1" property'):
        avsplat.read_ply(no_scale)


def test_write_errors(tmp_path):
    cloud = random_cloud(5, 0, seed=2, extras=())
    bad = cloud.copy()
    bad.means[3, 1] = np.nan
    with pytest.raises(ValueError, match=r"means\[3\]"):
        avsplat.write_ply(tmp_path / "nan.ply", bad)
    clash = cloud.copy()
    clash.set_extra("opacity", np.zeros(5))
    with pytest.raises(ValueError, match="opacity"):
        avsplat.write_ply(tmp_path / "clash.ply", clash)
    with pytest.raises(OSError, match="no_dir"):
        avsplat.write_ply(tmp_path / "no_dir" / "x.ply", cloud)
    with pytest.raises(TypeError):
        avsplat.write_ply(tmp_path / "x.ply", "not a cloud")


def test_read_ply_data_reads_any_element_and_lists_as_columns(tmp_path):
    # A hand-made big-endian mesh file, decoded independently with numpy.
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.5]], ">f4")
    header = (b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\n"
              b"property float y\nproperty float z\nelement face 2\n"
              b"property list uchar int vertex_indices\nproperty ushort flag\nend_header\n")
    faces = (bytes([3]) + np.array([0, 1, 2], ">i4").tobytes() + np.array([7], ">u2").tobytes()
             + bytes([1]) + np.array([2], ">i4").tobytes() + np.array([65535], ">u2").tobytes())
    path = tmp_path / "mesh.ply"
    path.write_bytes(header + verts.tobytes() + faces)
    data = avsplat.read_ply_data(path)
    assert list(data) == ["vertex", "face"]
    for k, name in enumerate("xyz"):
        np.testing.assert_array_equal(data["vertex"][name], verts[:, k].astype(np.float64))
    values, offsets = data["face"]["vertex_indices"]
    np.testing.assert_array_equal(values, [0, 1, 2, 2])
    np.testing.assert_array_equal(offsets, [0, 3, 4])
    np.testing.assert_array_equal(data["face"]["flag"], [7, 65535])
    path.write_bytes(header + verts.tobytes() + faces[:-3])
    with pytest.raises(OSError, match="mesh.ply: truncated file"):
        avsplat.read_ply_data(path)


def test_an_exception_in_a_with_block_removes_the_writers_files_at_once(tmp_path):
    import os
    out = tmp_path / "o.ply"
    cloud = avsplat.GaussianCloud.empty(10)
    writer = avsplat.GaussianPlyWriter(str(out))
    with pytest.raises(KeyError):
        with writer:
            writer.append(cloud)
            raise KeyError("stop")
    assert os.listdir(tmp_path) == []  # while the writer is still referenced
    with pytest.raises(RuntimeError, match="after commit or abort"):
        writer.append(cloud)


def test_abort_removes_the_writers_files_and_keeps_the_old_file(tmp_path):
    import os
    out = tmp_path / "o.ply"
    out.write_bytes(b"previous")
    writer = avsplat.GaussianPlyWriter(str(out))
    writer.append(avsplat.GaussianCloud.empty(10))
    writer.abort()
    assert sorted(os.listdir(tmp_path)) == ["o.ply"] and out.read_bytes() == b"previous"
    with pytest.raises(RuntimeError, match="after abort"):
        writer.commit()
