"""PlayCanvas LOD sets and SOG version 1 against splat-transform 3.7.0, both ways.

- SOG version 1: the real folder from PlayCanvas's examples, and a version 1 folder this test
  writes (version 2 images under a version 1 meta.json, the layout of avsplat/io/sog.h), read by
  avsplat equal splat-transform's decode of the same files (-> .ply) field by field;
- LOD sets avsplat writes: splat-transform reads every level (-L) with the same count, the same
  rows in the same order, and the attributes of the levels avsplat made within SOG's quantisation;
- LOD sets splat-transform writes: avsplat reads every level as splat-transform reads it;
- malformed lod-meta.json and version 1 meta.json: errors naming the file, the field and index.
"""
import json
import os
import shutil
import subprocess

import numpy as np
import pytest

import avsplat

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
REAL_V1 = os.path.join(ROOT, "..", "shared", "data", "real", "playcanvas-logo-sogv1")

# Two decoders of the same bytes: float32 against float64 arithmetic, the opacity logit
# splat-transform keeps in its PLY (our sigmoid of it), exp() of the log scale.
TOL = {
    "means": dict(rtol=1e-6, atol=1e-6),
    "scales": dict(rtol=1e-5, atol=1e-12),
    "rotations": dict(rtol=0, atol=2e-6),
    "opacities": dict(rtol=0, atol=2e-6),
    "sh": dict(rtol=1e-6, atol=1e-7),
}


def random_cloud(n, degree, seed, spread=3.0):
    rng = np.random.default_rng(seed)
    k = (degree + 1) ** 2
    return avsplat.GaussianCloud(
        (rng.standard_normal((n, 3)) * spread).astype(np.float32),
        np.exp(rng.uniform(-5, -1, (n, 3))).astype(np.float32),
        rng.standard_normal((n, 4)).astype(np.float32),
        rng.uniform(0.05, 1, n).astype(np.float32),
        (rng.standard_normal((n, k, 3)) * 0.3).astype(np.float32),
    )


def assert_same_decode(ours, theirs):
    assert len(ours) == len(theirs)
    assert ours.sh_degree == theirs.sh_degree
    for field, tol in TOL.items():
        a, b = getattr(ours, field), getattr(theirs, field)
        if field == "rotations":
            b = b / np.linalg.norm(b, axis=1, keepdims=True)
        np.testing.assert_allclose(a, b, err_msg=field, **tol)


def st_decode(splat_transform, tmp_path, src, *args, name="st.ply"):
    out = tmp_path / name
    splat_transform(*args, src, out)
    return avsplat.read_ply(str(out))


# --- SOG version 1 -------------------------------------------------------------------------------


@pytest.mark.skipif(not os.path.isdir(REAL_V1), reason="the real SOG v1 folder (../shared/data/real) is absent")
def test_real_sog_v1_folder_reads_as_splat_transform_reads_it(tmp_path, splat_transform):
    ours = avsplat.read_gaussians(REAL_V1)
    assert avsplat.detect_gaussian_format(REAL_V1).format == "sog"
    assert len(ours) == 307128 and ours.sh_degree == 0
    theirs = st_decode(splat_transform, tmp_path, os.path.join(REAL_V1, "meta.json"))
    assert_same_decode(ours, theirs)


def v1_from_v2(v2_folder, v1_folder):
    """A SOG version 1 folder: the version 2 images under a version 1 meta.json whose linear
    ranges (chosen here, not fitted) replace the codebooks. Both decoders read the same bytes."""
    shutil.copytree(v2_folder, v1_folder)
    m2 = json.loads((v1_folder / "meta.json").read_text())
    n = m2["count"]
    meta = {
        "means": {"shape": [n, 3], "dtype": "float32", "mins": m2["means"]["mins"], "maxs": m2["means"]["maxs"],
                  "files": m2["means"]["files"]},
        "scales": {"shape": [n, 3], "dtype": "float32", "mins": [-6.0, -5.5, -5.0], "maxs": [-1.0, -0.5, 0.0],
                   "files": m2["scales"]["files"]},
        "quats": {"shape": [n, 4], "dtype": "uint8", "encoding": "quaternion_packed", "files": m2["quats"]["files"]},
        "sh0": {"shape": [n, 1, 4], "dtype": "float32", "mins": [-1.5, -1.0, -0.5, -4.0], "maxs": [1.5, 1.0, 2.0, 5.0],
                "files": m2["sh0"]["files"]},
    }
    if "shN" in m2:
        meta["shN"] = {"shape": [n, 45], "dtype": "float32", "mins": -0.8, "maxs": 0.9, "quantization": 8,
                       "files": m2["shN"]["files"]}
    (v1_folder / "meta.json").write_text(json.dumps(meta))
    return meta


@pytest.mark.parametrize("degree", [0, 1, 3])
def test_written_sog_v1_folder_reads_as_splat_transform_reads_it(tmp_path, splat_transform, degree):
    cloud = random_cloud(3000, degree, seed=degree)
    avsplat.write_sog(str(tmp_path / "v2"), cloud)
    meta = v1_from_v2(tmp_path / "v2", tmp_path / "v1")
    ours = avsplat.read_gaussians(str(tmp_path / "v1"))
    assert ours.sh_degree == degree
    theirs = st_decode(splat_transform, tmp_path, tmp_path / "v1" / "meta.json")
    assert_same_decode(ours, theirs)
    # The ranges are used as documented: scales exp(mins + (maxs - mins) b / 255).
    lo, hi = np.array(meta["scales"]["mins"]), np.array(meta["scales"]["maxs"])
    b = (np.log(ours.scales.astype(np.float64)) - lo) / (hi - lo) * 255
    np.testing.assert_allclose(b, np.round(b), atol=1e-3)


def test_sog_v1_errors_name_the_file_and_field(tmp_path):
    cloud = random_cloud(500, 1, seed=5)
    avsplat.write_sog(str(tmp_path / "v2"), cloud)
    v1_from_v2(tmp_path / "v2", tmp_path / "v1")
    meta_path = tmp_path / "v1" / "meta.json"
    good = json.loads(meta_path.read_text())

    def refused(edit, *words):
        m = json.loads(json.dumps(good))
        edit(m)
        meta_path.write_text(json.dumps(m))
        with pytest.raises(avsplat.FileError) as e:
            avsplat.read_gaussians(str(tmp_path / "v1"))
        for w in (str(meta_path.parent), *words):
            assert w in str(e.value), str(e.value)

    refused(lambda m: m["means"].pop("shape"), '"means.shape"', "is missing")
    refused(lambda m: m["means"].update(shape=[-3, 3]), '"means.shape[0]"')
    refused(lambda m: m["scales"].update(mins=[0, 0]), '"scales.mins"', "3 numbers")
    refused(lambda m: m["sh0"].update(maxs=[1, 1, 1, "x"]), '"sh0.maxs[3]"')
    refused(lambda m: m["sh0"].update(mins=[0, 0, 9, 0]), '"sh0.mins[2]"', "greater")
    refused(lambda m: m["shN"].update(mins="a"), '"shN.mins"')
    # A centroids image of a width no band count has: the labels image stands in for it.
    refused(lambda m: m["shN"].update(files=[m["shN"]["files"][1], m["shN"]["files"][1]]), "shN_labels.webp",
            "width")


# --- LOD sets -------------------------------------------------------------------------------------


def test_lod_set_avsplat_writes_reads_in_splat_transform(tmp_path, splat_transform):
    cloud = random_cloud(6000, 1, seed=11)
    path = tmp_path / "set" / "lod-meta.json"
    build = avsplat.build_lod(cloud, str(path), levels=3, node_size=1500, chunk_size=2000)
    counts = [len(c) for c in build.levels]
    assert counts == [6000, 3000, 1500]
    info = avsplat.read_lod_set_info(str(path))
    assert info.levels == 3 and list(info.counts) == counts and info.leaves >= 7
    meta = json.loads(path.read_text())
    assert meta["counts"] == counts and meta["lodLevels"] == 3 and meta["version"] == 1
    ours = avsplat.read_lod_set(str(path))
    for level in range(3):
        theirs = st_decode(splat_transform, tmp_path, path, "-L", level, name=f"l{level}.ply")
        assert len(theirs) == counts[level]
        assert_same_decode(ours[level], theirs)
        # Within SOG's quantisation of the level avsplat made: each decoded Gaussian at a
        # Gaussian of the level (positions: 16 bits of log1p over each chunk's bounds).
        made = build.levels[level]
        d2 = ((theirs.means[:, None, :].astype(np.float64) - made.means[None, :, :]) ** 2).sum(-1)
        nearest = d2.argmin(1)
        assert len(np.unique(nearest)) == counts[level]
        assert np.sqrt(d2.min(1)).max() < 3 * np.log1p(np.abs(made.means).max()) * np.e ** 3 / 65535 * 4
        np.testing.assert_allclose(theirs.opacities, made.opacities[nearest], atol=0.5 / 255 + 1e-6)
    # Without -L splat-transform reads level 0, as read_gaussians does.
    theirs = st_decode(splat_transform, tmp_path, path, name="default.ply")
    assert_same_decode(avsplat.read_gaussians(str(path)), theirs)


def test_lod_tree_leaves_are_bounded_and_ranges_tile_each_chunk(tmp_path):
    cloud = random_cloud(5000, 0, seed=3)
    path = tmp_path / "lod-meta.json"
    avsplat.build_lod(cloud, str(path), levels=4, node_size=700, chunk_size=900)
    meta = json.loads(path.read_text())
    leaves = []

    def walk(node):
        if "children" in node:
            assert len(node["children"]) == 2
            for c in node["children"]:
                # A child's bound lies in its parent's.
                assert all(a >= b for a, b in zip(c["bound"]["min"], node["bound"]["min"]))
                assert all(a <= b for a, b in zip(c["bound"]["max"], node["bound"]["max"]))
                walk(c)
        else:
            leaves.append(node)

    walk(meta["tree"])
    ranges = {}
    for leaf in leaves:
        assert sum(r["count"] for r in leaf["lods"].values()) <= 700
        for level, r in leaf["lods"].items():
            name = meta["filenames"][r["file"]]
            assert name.startswith(f"{level}_")
            ranges.setdefault(r["file"], []).append((r["offset"], r["count"]))
    for f, rs in ranges.items():
        rs.sort()
        end = 0
        for off, cnt in rs:
            assert off == end
            end += cnt
        assert end == avsplat.read_sog(str(path.parent / meta["filenames"][f])).__len__()
    # Every Gaussian of a leaf lies in its bound (means; the bound also holds the extents).
    levels = avsplat.read_lod_set(str(path))
    for leaf in leaves:
        for level, r in leaf["lods"].items():
            lo, hi = np.array(leaf["bound"]["min"]), np.array(leaf["bound"]["max"])
            chunk = avsplat.read_sog(str(path.parent / meta["filenames"][r["file"]]))
            m = chunk.means[r["offset"]:r["offset"] + r["count"]]
            assert (m >= lo - 1e-3).all() and (m <= hi + 1e-3).all()
    assert [len(c) for c in levels] == meta["counts"] == [5000, 2500, 1250, 625]


def test_lod_set_splat_transform_writes_reads_in_avsplat(tmp_path, splat_transform):
    l0 = random_cloud(4000, 2, seed=21)
    l1 = avsplat.simplify(l0, ratio=0.5).cloud
    avsplat.write_ply(str(tmp_path / "l0.ply"), l0)
    avsplat.write_ply(str(tmp_path / "l1.ply"), l1)
    path = tmp_path / "st" / "lod-meta.json"
    # -l tags the input before it.
    splat_transform(tmp_path / "l0.ply", "-l", 0, tmp_path / "l1.ply", "-l", 1, "--lod-chunk-count", 2, path)
    assert avsplat.detect_gaussian_format(str(path)).format == "lod_set"
    info = avsplat.read_lod_set_info(str(path))
    assert info.levels == 2 and list(info.counts) == [4000, 2000]
    ours = avsplat.read_lod_set(str(path), [0, -1])
    for level in (0, 1):
        theirs = st_decode(splat_transform, tmp_path, path, "-L", level, name=f"st{level}.ply")
        assert_same_decode(ours[level], theirs)


def test_write_lod_set_keeps_given_levels_and_build_lod_measures_each_level(tmp_path):
    # write_lod_set takes any levels (here not made by build_lod): each reads back with its count
    # and its SOG chunks named by LodSetInfo.filenames.
    levels = [random_cloud(1200, 0, seed=30), random_cloud(100, 0, seed=31)]
    path = tmp_path / "lod-meta.json"
    avsplat.write_lod_set(str(path), levels, node_size=400, chunk_size=500)
    info = avsplat.read_lod_set_info(str(path))
    assert list(info.counts) == [1200, 100]
    # 4 leaves of about 300 level-0 Gaussians: a chunk closes once it holds 500 or more.
    assert sorted(info.filenames) == ["0_0/meta.json", "0_1/meta.json", "1_0/meta.json"]
    back = avsplat.read_lod_set(str(path), [1])[0]
    assert len(back) == 100
    # With cameras, each level's rendered error against the level before it is measured.
    cloud = random_cloud(2000, 0, seed=32, spread=0.5)
    cloud.means[:, 2] += 4.0
    cams = [avsplat.Camera(60, 60, 32, 24, 64, 48)]
    build = avsplat.build_lod(cloud, levels=3, cameras=cams)
    assert isinstance(build, avsplat.LodBuild)
    assert build.seconds[0] == 0 and all(t > 0 for t in build.seconds[1:])
    assert build.errors[0] == 0 and all(0 < e < 1 for e in build.errors[1:])
    assert all(np.isnan(e) for e in avsplat.build_lod(cloud, levels=2).errors)
    with pytest.raises(ValueError, match="ratio"):
        avsplat.build_lod(cloud, ratio=1.0)
    with pytest.raises(ValueError, match="SH degree"):
        avsplat.write_lod_set(str(path), [random_cloud(10, 1, 0), random_cloud(5, 0, 0)])


def test_lod_set_errors_name_the_file_and_field(tmp_path):
    path = tmp_path / "lod-meta.json"
    avsplat.build_lod(random_cloud(800, 0, seed=4), str(path), levels=2, node_size=300, chunk_size=400)
    good = json.loads(path.read_text())

    def first_leaf(m):
        n = m["tree"]
        while "children" in n:
            n = n["children"][0]
        return n

    def refused(edit, *words):
        m = json.loads(json.dumps(good))
        edit(m)
        path.write_text(json.dumps(m))
        with pytest.raises(avsplat.FileError) as e:
            avsplat.read_lod_set(str(path))
        for w in (str(path), *words):
            assert w in str(e.value), str(e.value)

    refused(lambda m: m.update(version=2), '"version"')
    refused(lambda m: m.update(lodLevels=0), '"lodLevels"')
    refused(lambda m: m["filenames"].__setitem__(0, "../x/meta.json"), '"filenames[0]"', "..")
    refused(lambda m: m["filenames"].__setitem__(1, "/etc/meta.json"), '"filenames[1]"', "relative")
    refused(lambda m: first_leaf(m)["lods"]["0"].update(file=99), '"tree.children[0]', '.lods.0.file"')
    refused(lambda m: first_leaf(m)["lods"]["0"].update(count=-1), '.lods.0.count"')
    refused(lambda m: first_leaf(m)["lods"].update({"7": first_leaf(m)["lods"]["0"]}), '.lods.7"', "not a level")
    refused(lambda m: m["counts"].__setitem__(1, 3), '"counts[1]"', "400")
    refused(lambda m: first_leaf(m)["lods"]["1"].update(file=first_leaf(m)["lods"]["0"]["file"]), '.lods.1.file"',
            "one level")
    refused(lambda m: first_leaf(m)["lods"]["0"].update(offset=1), '.offset"', "inside the range")
    with pytest.raises(avsplat.FileError, match="level 5 asked for"):
        path.write_text(json.dumps(good))
        avsplat.read_lod_set(str(path), [5])


def test_cli_lod_info_and_convert(tmp_path):
    cloud = random_cloud(3000, 0, seed=8)
    avsplat.write_ply(str(tmp_path / "in.ply"), cloud)
    build = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__))))
    exe = [os.path.join(build, "apps", "avsplat")]
    out = tmp_path / "set" / "lod-meta.json"
    r = subprocess.run([*exe, "lod", str(tmp_path / "in.ply"), str(out), "--levels", "3", "--node-size", "1000"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "level 2  750 Gaussians" in r.stdout
    r = subprocess.run([*exe, "info", str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "LOD set" in r.stdout and "levels         3" in r.stdout and "1500 Gaussians" in r.stdout
    r = subprocess.run([*exe, "convert", str(out), str(tmp_path / "l12.ply"), "--lod-levels", "1,2"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert len(avsplat.read_ply(str(tmp_path / "l12.ply"))) == 1500 + 750
