"""Binary glTF (.glb) with KHR_gaussian_splatting: round trips, files built here from the
extension's attribute table (independent of our writer), splat-transform 3.7.0's .glb writer as
the peer, and damaged files whose errors name the file and the field."""
import json
import os
import struct
import subprocess

import numpy as np
import pytest

import avsplat

C0 = 0.28209479177387814
EXT = "KHR_gaussian_splatting"
# glTF's axes (+Y up, +Z forward, +X left) from avsplat's (x right, y down, z forward): a turn of
# 180 degrees about z. Positions and quaternion x, y negate; SH coefficient j by the parity of its
# basis function in x and y (y, z, x | xy, yz, z^2, xz, x^2-y^2 | y(..), xyz, y(..), z(..), x(..),
# z(..), x(..)).
POS_SIGN = np.array([-1.0, -1.0, 1.0])
QUAT_SIGN = np.array([1.0, -1.0, -1.0, 1.0])  # w, x, y, z
SH_SIGN = np.array([1.0, -1, 1, -1, 1, -1, 1, -1, 1, -1, 1, -1, 1, -1, 1, -1])


def covariances(scales, q):
    """R diag(s^2) R^T per Gaussian: what a rotation and scales describe, whatever the quaternion's
    sign or the order of equal axes."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    r = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                  2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                  2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1).reshape(-1, 3, 3)
    return np.einsum("nij,nj,nkj->nik", r, np.asarray(scales, np.float64) ** 2, r)


def random_cloud(n, degree, seed):
    rng = np.random.default_rng(seed)
    k = (degree + 1) ** 2
    return avsplat.GaussianCloud(
        rng.uniform(-20, 20, (n, 3)),
        np.exp(rng.uniform(-6, 2, (n, 3))),
        rng.normal(size=(n, 4)),
        rng.uniform(0.01, 0.99, n),
        rng.uniform(-1.5, 1.5, (n, k, 3)),
    )


def glb_bytes(doc, bin_bytes):
    """A GLB container around `doc` (a dict) and `bin_bytes`, per glTF 2.0's GLB layout."""
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    bin_bytes += b"\0" * (-len(bin_bytes) % 4)
    total = 12 + 8 + len(text) + 8 + len(bin_bytes)
    return (struct.pack("<III", 0x46546C67, 2, total) + struct.pack("<II", len(text), 0x4E4F534A) + text
            + struct.pack("<II", len(bin_bytes), 0x004E4942) + bin_bytes)


def chunks(path):
    """(JSON dict, BIN bytes) of a GLB file."""
    data = path.read_bytes()
    magic, version, total = struct.unpack_from("<III", data)
    assert (magic, version, total) == (0x46546C67, 2, len(data))
    jlen, jtype = struct.unpack_from("<II", data, 12)
    assert jtype == 0x4E4F534A
    doc = json.loads(data[20:20 + jlen])
    blen, btype = struct.unpack_from("<II", data, 20 + jlen)
    assert btype == 0x004E4942
    return doc, data[28 + jlen:28 + jlen + blen]


def attribute(doc, bin_bytes, name):
    """The float32 values of attribute `name` (tightly packed), shaped (count, components)."""
    prim = doc["meshes"][0]["primitives"][0]
    acc = doc["accessors"][prim["attributes"][name]]
    view = doc["bufferViews"][acc["bufferView"]]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[acc["type"]]
    dtype = {5126: np.float32, 5121: np.uint8}[acc["componentType"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    return np.frombuffer(bin_bytes, dtype, acc["count"] * width, start).reshape(acc["count"], width)


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_round_trip_is_exact_and_detected_by_content(tmp_path, degree):
    cloud = random_cloud(257, degree, degree)
    path = tmp_path / "a.glb"
    avsplat.write_glb(path, cloud)
    back = avsplat.read_glb(path)
    assert back.sh_degree == degree and len(back) == len(cloud)
    for name in ("means", "scales", "rotations", "opacities", "sh"):
        np.testing.assert_array_equal(getattr(back, name), getattr(cloud, name), err_msg=name)
    info = avsplat.detect_gaussian_format(path)
    assert info.format == "glb" and info.version == "2"
    renamed = tmp_path / "renamed.ply"
    renamed.write_bytes(path.read_bytes())
    np.testing.assert_array_equal(avsplat.read_gaussians(renamed).sh, cloud.sh)
    avsplat.write_gaussians(tmp_path / "b.glb", cloud)
    assert (tmp_path / "b.glb").read_bytes() == path.read_bytes()
    # The layout: SH coefficient (l, n) is the cloud's coefficient l*l + n; COLOR_0 the DC colour.
    doc, bin_bytes = chunks(path)
    assert doc["extensionsUsed"] == [EXT] and doc["meshes"][0]["primitives"][0]["mode"] == 0
    for l in range(degree + 1):
        for n in range(2 * l + 1):
            got = attribute(doc, bin_bytes, f"{EXT}:SH_DEGREE_{l}_COEF_{n}")
            np.testing.assert_array_equal(got, cloud.sh[:, l * l + n] * SH_SIGN[l * l + n])
    assert f"{EXT}:SH_DEGREE_{degree + 1}_COEF_0" not in doc["meshes"][0]["primitives"][0]["attributes"]
    np.testing.assert_array_equal(attribute(doc, bin_bytes, "POSITION"), cloud.means * POS_SIGN)
    np.testing.assert_array_equal(attribute(doc, bin_bytes, f"{EXT}:ROTATION"), (cloud.rotations * QUAT_SIGN)[:, [1, 2, 3, 0]])
    rgba = attribute(doc, bin_bytes, "COLOR_0")
    want = np.clip(np.round(np.column_stack([0.5 + C0 * cloud.sh[:, 0].astype(np.float64), cloud.opacities]) * 255), 0, 255)
    np.testing.assert_array_equal(rgba, want)
    pos = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
    np.testing.assert_array_equal(pos["min"], (cloud.means * POS_SIGN).min(axis=0))
    np.testing.assert_array_equal(pos["max"], (cloud.means * POS_SIGN).max(axis=0))


def test_log_scales_follow_the_draft_when_asked(tmp_path):
    cloud = random_cloud(40, 1, 7)
    avsplat.write_glb(tmp_path / "log.glb", cloud, log_scales=True)
    doc, bin_bytes = chunks(tmp_path / "log.glb")
    np.testing.assert_allclose(attribute(doc, bin_bytes, f"{EXT}:SCALE"), np.log(cloud.scales), rtol=1e-6)
    np.testing.assert_allclose(avsplat.read_glb(tmp_path / "log.glb", log_scales=True).scales, cloud.scales, rtol=1e-6)
    # Read as splat-transform's linear scales, the same file gives the logarithms.
    np.testing.assert_allclose(avsplat.read_glb(tmp_path / "log.glb").scales, np.log(cloud.scales), rtol=1e-6)


def hand_built(tmp_path):
    """Two Gaussian primitives in the extension's other encodings: interleaved float positions and
    int16-normalized rotations in one view, uint8-normalized opacities, int8 scales (not
    normalized), COLOR_0 in place of SH_DEGREE_0_COEF_0 in the first; the second of SH degree 1."""
    # Primitive 0: 2 Gaussians. Interleaved record: 3 float32 + 4 int16 = 20 bytes.
    rec = struct.pack("<3f4h", 1.0, 2.0, 3.0, 0, 0, 32767, 0) + struct.pack("<3f4h", -1.0, 0.5, 0.25, -32767, 0, 0, 0)
    opac = bytes([255, 51]) + b"\0\0"
    scales = struct.pack("<6b", 1, 2, 3, -1, 0, 1) + b"\0\0"
    color = bytes([255, 0, 128, 255, 64, 64, 64, 51])
    # Primitive 1: 1 Gaussian, all float, SH degree 1.
    p1 = struct.pack("<3f", 7, 8, 9)
    r1 = struct.pack("<4f", 0, 0, 0, 1)
    s1 = struct.pack("<3f", 0.5, 0.25, 2)
    o1 = struct.pack("<f", 0.75)
    sh1 = [struct.pack("<3f", *(0.1 * (j + 1) + 0.01 * np.arange(3))) for j in range(4)]
    blobs = [rec, opac, scales, color, p1, r1, s1, o1, *sh1]
    offsets, bin_bytes = [], b""
    for b in blobs:
        offsets.append(len(bin_bytes))
        bin_bytes += b
    views = [{"buffer": 0, "byteOffset": offsets[0], "byteLength": len(rec), "byteStride": 20}]
    views += [{"buffer": 0, "byteOffset": o, "byteLength": len(b)} for o, b in zip(offsets[1:], blobs[1:])]
    acc = [
        {"bufferView": 0, "componentType": 5126, "count": 2, "type": "VEC3"},
        {"bufferView": 0, "byteOffset": 12, "componentType": 5122, "normalized": True, "count": 2, "type": "VEC4"},
        {"bufferView": 1, "componentType": 5121, "normalized": True, "count": 2, "type": "SCALAR"},
        {"bufferView": 2, "componentType": 5120, "count": 2, "type": "VEC3"},
        {"bufferView": 3, "componentType": 5121, "normalized": True, "count": 2, "type": "VEC4"},
    ] + [{"bufferView": 4 + i, "componentType": 5126, "count": 1, "type": t}
         for i, t in enumerate(["VEC3", "VEC4", "VEC3", "SCALAR", "VEC3", "VEC3", "VEC3", "VEC3"])]
    prim0 = {"mode": 0, "extensions": {EXT: {"kernel": "ellipse", "colorSpace": "srgb_rec709_display"}},
             "attributes": {"POSITION": 0, f"{EXT}:ROTATION": 1, f"{EXT}:OPACITY": 2, f"{EXT}:SCALE": 3, "COLOR_0": 4}}
    attrs1 = {"POSITION": 5, f"{EXT}:ROTATION": 6, f"{EXT}:SCALE": 7, f"{EXT}:OPACITY": 8,
              f"{EXT}:SH_DEGREE_0_COEF_0": 9}
    attrs1.update({f"{EXT}:SH_DEGREE_1_COEF_{n}": 10 + n for n in range(3)})
    prim1 = {"mode": 0, "extensions": {EXT: {"kernel": "ellipse"}}, "attributes": attrs1}
    other = {"mode": 0, "attributes": {"POSITION": 5}}  # a plain point cloud: not Gaussians
    doc = {"asset": {"version": "2.0"}, "extensionsUsed": [EXT], "buffers": [{"byteLength": len(bin_bytes)}],
           "bufferViews": views, "accessors": acc, "nodes": [{"mesh": 0}, {"mesh": 1}],
           "meshes": [{"primitives": [prim0, other]}, {"primitives": [prim1]}]}
    return doc, bin_bytes


def test_reads_the_extensions_other_encodings_built_by_hand(tmp_path):
    doc, bin_bytes = hand_built(tmp_path)
    path = tmp_path / "hand.glb"
    path.write_bytes(glb_bytes(doc, bin_bytes))
    c = avsplat.read_gaussians(path)
    assert len(c) == 3 and c.sh_degree == 1
    np.testing.assert_array_equal(c.means, np.array([[1, 2, 3], [-1, 0.5, 0.25], [7, 8, 9]]) * POS_SIGN)
    # x, y, z, w in the file -> w, x, y, z; int16 normalized c / 32767, clamped at -1; then glTF's
    # axes to ours.
    np.testing.assert_array_equal(c.rotations, np.array([[0, 0, 0, 1], [0, -1, 0, 0], [1, 0, 0, 0]]) * QUAT_SIGN)
    np.testing.assert_allclose(c.opacities, [1, 0.2, 0.75], rtol=1e-7)
    np.testing.assert_array_equal(c.scales, [[1, 2, 3], [-1, 0, 1], [0.5, 0.25, 2]])
    # COLOR_0 stands for the DC term: (rgb - 0.5) / C0; primitive 0 has no higher SH (zero-padded).
    np.testing.assert_allclose(c.sh[:2, 0], (np.array([[255, 0, 128], [64, 64, 64]]) / 255 - 0.5) / C0, rtol=1e-6)
    np.testing.assert_array_equal(c.sh[:2, 1:], 0)
    want1 = np.array([0.1 * (j + 1) + 0.01 * np.arange(3) for j in range(4)], np.float32)
    np.testing.assert_array_equal(c.sh[2], want1 * SH_SIGN[:4, None])


def write_doc(tmp_path, name, doc, bin_bytes):
    path = tmp_path / name
    path.write_bytes(glb_bytes(doc, bin_bytes))
    return path


def test_damaged_files_name_the_file_and_the_field(tmp_path):
    good = tmp_path / "good.glb"
    avsplat.write_glb(good, random_cloud(10, 1, 3))
    data = good.read_bytes()
    doc, bin_bytes = chunks(good)
    cases = []
    cut = tmp_path / "cut.glb"
    cut.write_bytes(data[: len(data) // 2])
    cases.append((cut, r"cut\.glb: length: the header claims \d+ bytes, the file holds"))
    magic = tmp_path / "magic.glb"
    magic.write_bytes(b"xxxx" + data[4:])
    cases.append((magic, r"magic\.glb: not a glTF binary file"))
    v1 = tmp_path / "v1.glb"
    v1.write_bytes(data[:4] + struct.pack("<I", 1) + data[8:])
    cases.append((v1, r"v1\.glb: version: 1 is not supported"))
    bad_json = tmp_path / "json.glb"
    bad_json.write_bytes(data[:20] + b"x" + data[21:])
    cases.append((bad_json, r"json\.glb: chunks\[0\]: invalid JSON"))

    def variant(name, change):
        d = json.loads(json.dumps(doc))
        change(d)
        return write_doc(tmp_path, name, d, bin_bytes)

    prim = lambda d: d["meshes"][0]["primitives"][0]  # noqa: E731
    scale_acc = prim(doc)["attributes"][f"{EXT}:SCALE"]
    cases.append((variant("count.glb", lambda d: d["accessors"][scale_acc].update(count=11)),
                  rf"count\.glb: accessors\[{scale_acc}\]\.count: 11 elements of 12 bytes at offset 0 run past bufferViews\[{scale_acc}\]"))
    # A count that would allocate 48 GB is refused by the same check, before anything is allocated.
    cases.append((variant("claim.glb", lambda d: d["accessors"][0].update(count=4_000_000_000)),
                  r"claim\.glb: accessors\[0\]\.count: 4000000000 elements"))
    cases.append((variant("view.glb", lambda d: d["bufferViews"][2].update(byteLength=10 ** 6)),
                  r"view\.glb: bufferViews\[2\]: bytes \d+ \+ 1000000 run past the binary chunk"))
    cases.append((variant("missing.glb", lambda d: prim(d)["attributes"].pop(f"{EXT}:OPACITY")),
                  r"missing\.glb: meshes\[0\]\.primitives\[0\]\.attributes: KHR_gaussian_splatting:OPACITY is missing"))
    cases.append((variant("partial.glb", lambda d: prim(d)["attributes"].pop(f"{EXT}:SH_DEGREE_1_COEF_2")),
                  r"partial\.glb: .*SH_DEGREE_1_COEF_2 is missing while SH degree 1 is given"))
    cases.append((variant("sparse.glb", lambda d: d["accessors"][0].update(sparse={"count": 1})),
                  r"sparse\.glb: accessors\[0\]\.sparse: sparse accessors are not supported"))
    cases.append((variant("uri.glb", lambda d: d["buffers"][0].update(uri="scene.bin")),
                  r"uri\.glb: buffers\[0\]: only the GLB's own binary chunk is read"))
    cases.append((variant("node.glb", lambda d: d["nodes"][0].update(translation=[1, 0, 0])),
                  r"node\.glb: nodes\[0\]\.translation: node transforms are not applied"))
    cases.append((variant("type.glb", lambda d: d["accessors"][scale_acc].update(type="VEC2")),
                  r"type\.glb: KHR_gaussian_splatting:SCALE: 2 components, expected 3"))
    cases.append((variant("index.glb", lambda d: prim(d)["attributes"].update({f"{EXT}:SCALE": 99})),
                  r"index\.glb: attributes\[\"KHR_gaussian_splatting:SCALE\"\]: accessors\[99\] does not exist"))
    cases.append((variant("mode.glb", lambda d: prim(d).update(mode=4)),
                  r"mode\.glb: meshes\[0\]\.primitives\[0\]\.mode: a Gaussian primitive must be POINTS"))
    cases.append((variant("plain.glb", lambda d: prim(d).pop("extensions")),
                  r"plain\.glb: meshes: no primitive carries the KHR_gaussian_splatting extension"))
    for path, pattern in cases:
        with pytest.raises(OSError, match=pattern):
            avsplat.read_gaussians(path)
    with pytest.raises(OSError, match=r"nothing\.glb: not a glTF binary file"):
        (tmp_path / "nothing.glb").write_bytes(b"not a glb at all")
        avsplat.read_gaussians(tmp_path / "nothing.glb")


def test_splat_transform_glb_reads_as_its_ply_source(tmp_path, splat_transform):
    """PLY -> splat-transform 3.7 -> .glb -> read_glb gives the PLY's cloud (splat-transform turns
    PLY 180 degrees about z into glTF's axes, and we turn it back; scales and opacities activated
    by splat-transform in float64, then float32); our own .glb of the same cloud has the same
    document structure and the same attribute values."""
    cloud = random_cloud(3000, 3, 21)
    avsplat.write_ply(tmp_path / "src.ply", cloud)
    src = avsplat.read_ply(tmp_path / "src.ply")
    splat_transform(tmp_path / "src.ply", tmp_path / "theirs.glb")
    theirs = avsplat.read_gaussians(tmp_path / "theirs.glb")
    assert len(theirs) == len(src) and theirs.sh_degree == 3
    np.testing.assert_array_equal(theirs.means, src.means)
    np.testing.assert_array_equal(theirs.sh, src.sh)
    np.testing.assert_allclose(theirs.scales, src.scales, rtol=1e-6)
    np.testing.assert_allclose(theirs.opacities, src.opacities, rtol=1e-6, atol=1e-7)
    scale2 = np.max(src.scales, axis=1) ** 2
    err = np.abs(covariances(theirs.scales, theirs.rotations) - covariances(src.scales, src.rotations)).max(axis=(1, 2))
    assert (err <= 1e-5 * scale2).all()

    avsplat.write_glb(tmp_path / "ours.glb", src)
    doc_t, bin_t = chunks(tmp_path / "theirs.glb")
    doc_o, bin_o = chunks(tmp_path / "ours.glb")
    prim_t, prim_o = doc_t["meshes"][0]["primitives"][0], doc_o["meshes"][0]["primitives"][0]
    assert sorted(prim_t["attributes"]) == sorted(prim_o["attributes"])
    assert prim_t["extensions"] == prim_o["extensions"] and prim_t["mode"] == prim_o["mode"]
    assert doc_t["extensionsUsed"] == doc_o["extensionsUsed"]
    for name in prim_t["attributes"]:
        acc_t = doc_t["accessors"][prim_t["attributes"][name]]
        acc_o = doc_o["accessors"][prim_o["attributes"][name]]
        for key in ("componentType", "type", "count", "normalized", "min", "max"):
            assert acc_t.get(key) == acc_o.get(key), (name, key)
        a, b = attribute(doc_t, bin_t, name), attribute(doc_o, bin_o, name)
        if name == "COLOR_0":  # 8-bit rounding of the same values: at most one step apart
            assert np.abs(a.astype(int) - b.astype(int)).max() <= 1
        elif name.endswith(("SCALE", "OPACITY")):
            np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7, err_msg=name)
        elif name.endswith("ROTATION"):  # two quaternions of one covariance (see covariances)
            ca = covariances(attribute(doc_t, bin_t, f"{EXT}:SCALE"), a[:, [3, 0, 1, 2]])
            cb = covariances(attribute(doc_o, bin_o, f"{EXT}:SCALE"), b[:, [3, 0, 1, 2]])
            assert (np.abs(ca - cb).max(axis=(1, 2)) <= 1e-5 * scale2).all()
        else:
            np.testing.assert_array_equal(a, b, err_msg=name)


def test_cli_convert_writes_and_reads_glb(tmp_path):
    build = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__))))
    exe = os.path.join(build, "apps", "avsplat")
    if not os.access(exe, os.X_OK):
        pytest.skip(f"no avsplat binary at {exe}")
    cloud = random_cloud(100, 2, 5)
    avsplat.write_ply(tmp_path / "in.ply", cloud)
    for cmd in (["convert", tmp_path / "in.ply", tmp_path / "mid.glb"],
                ["convert", tmp_path / "mid.glb", tmp_path / "out.ply"]):
        done = subprocess.run([exe, *map(str, cmd)], capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
    back = avsplat.read_ply(tmp_path / "out.ply")
    np.testing.assert_array_equal(back.means, avsplat.read_ply(tmp_path / "in.ply").means)
    np.testing.assert_array_equal(back.sh, avsplat.read_ply(tmp_path / "in.ply").sh)
