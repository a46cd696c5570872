""".ksplat (mkkellogg's GaussianSplats3D), read only. No peer writes it, so the files are built
here from the layout of GaussianSplats3D's SplatBuffer (version 0.1: a 4096-byte header, 1024-byte
section headers, per section the partially filled buckets' lengths, the bucket centres and the
records), decoded by hand, and compared with splat-transform 3.7.0's own .ksplat reader."""
import struct

import numpy as np
import pytest

import avsplat

C0 = 0.28209479177387814
SH_VALUES = {0: 0, 1: 9, 2: 24}


def make_section(rng, n, degree, level, full=0, partial=(), capacity=None, bucket_capacity=4, block=4.0,
                 quant_range=0):
    """Random Gaussians of one section and their expected decode. Positions of level 1/2 lie within
    half a block of their bucket's centre; the buckets are `full` full ones of `bucket_capacity`,
    then the partially filled ones of the given lengths."""
    lengths = [bucket_capacity] * full + list(partial)
    assert sum(lengths) >= n or level == 0
    buckets = len(lengths)
    centres = rng.uniform(-30, 30, (max(buckets, 1), 3)).astype(np.float32)
    bucket_of = np.repeat(np.arange(buckets), lengths)[:n] if level else np.zeros(n, int)
    rng_q = quant_range or 32767
    step = block / 2.0 / rng_q
    sec = {"n": n, "degree": degree, "full": full, "partial": list(partial), "bucket_capacity": bucket_capacity,
           "block": block, "quant_range": quant_range, "centres": centres[:buckets], "capacity": capacity or n}
    if level == 0:
        sec["pos"] = rng.uniform(-50, 50, (n, 3)).astype(np.float32)
        want_pos = sec["pos"]
    else:
        sec["q"] = rng.integers(0, 65536, (n, 3)).astype(np.uint16)
        want_pos = ((sec["q"].astype(np.float64) - rng_q) * step + centres[bucket_of].astype(np.float64)).astype(np.float32)
    scale = np.exp(rng.uniform(-5, 1, (n, 3)))
    rot = rng.normal(size=(n, 4))
    sh = rng.uniform(-1.4, 1.4, (n, SH_VALUES[degree]))
    if level == 0:
        sec["scale"], sec["rot"], sec["sh"] = scale.astype(np.float32), rot.astype(np.float32), sh.astype(np.float32)
        want_scale, want_rot, want_sh = sec["scale"], sec["rot"], sec["sh"]
    else:
        sec["scale"], sec["rot"] = scale.astype(np.float16), rot.astype(np.float16)
        want_scale, want_rot = sec["scale"].astype(np.float32), sec["rot"].astype(np.float32)
        if level == 1:
            sec["sh"] = sh.astype(np.float16)
            want_sh = sec["sh"].astype(np.float32)
        else:
            sec["sh"] = np.round((sh + 1.5) / 3.0 * 255).astype(np.uint8)
            want_sh = (-1.5 + 3.0 * (sec["sh"] / 255.0)).astype(np.float32)
    sec["rgba"] = rng.integers(0, 256, (n, 4)).astype(np.uint8)
    # Expected SH (n, 9, 3): bands 1..2 stored channel-major within each band.
    k = (degree + 1) ** 2
    want = np.zeros((n, k, 3))
    want[:, 0] = (sec["rgba"][:, :3] / 255.0 - 0.5) / C0
    start = 0
    for band in range(1, degree + 1):
        width = 2 * band + 1
        for ch in range(3):
            for m in range(width):
                want[:, band * band + m, ch] = want_sh[:, start + ch * width + m]
        start += 3 * width
    sec["want"] = {"means": want_pos, "scales": want_scale, "rotations": want_rot,
                   "opacities": sec["rgba"][:, 3] / 255.0, "sh": want}
    return sec


def ksplat_bytes(sections, level, sh_range=(0.0, 0.0), major=0, minor=1):
    """A .ksplat file of `sections` (from make_section) at compression `level`."""
    header = bytearray(4096)
    header[0], header[1] = major, minor
    struct.pack_into("<IIII", header, 4, len(sections), len(sections), sum(s["capacity"] for s in sections),
                     sum(s["n"] for s in sections))
    struct.pack_into("<H", header, 20, level)
    struct.pack_into("<3f", header, 24, 0, 0, 0)
    struct.pack_into("<2f", header, 36, *sh_range)
    section_headers, bodies = b"", b""
    for s in sections:
        per_sh = {0: 4, 1: 2, 2: 1}[level]
        stride = (44 if level == 0 else 24) + SH_VALUES[s["degree"]] * per_sh
        sh_head = bytearray(1024)
        buckets = len(s["centres"]) if level else 0
        struct.pack_into("<IIII", sh_head, 0, s["n"], s["capacity"], s["bucket_capacity"] if level else 0, buckets)
        struct.pack_into("<f", sh_head, 16, s["block"] if level else 0)
        struct.pack_into("<H", sh_head, 20, 12 if level else 0)
        struct.pack_into("<I", sh_head, 24, s["quant_range"])
        struct.pack_into("<III", sh_head, 28, 0, s["full"] if level else 0, len(s["partial"]) if level else 0)
        struct.pack_into("<H", sh_head, 40, s["degree"])
        section_headers += bytes(sh_head)
        body = b""
        if level:
            body += np.array(s["partial"], np.uint32).tobytes() + s["centres"].astype("<f4").tobytes()
        records = bytearray(stride * s["capacity"])
        for i in range(s["n"]):
            pos = s["pos"][i].astype("<f4").tobytes() if level == 0 else s["q"][i].astype("<u2").tobytes()
            rec = pos + s["scale"][i].tobytes() + s["rot"][i].tobytes() + s["rgba"][i].tobytes() + s["sh"][i].tobytes()
            assert len(rec) == stride
            records[i * stride:(i + 1) * stride] = rec
        bodies += body + bytes(records)
    return bytes(header) + section_headers + bodies


def expected(sections):
    degree = max(s["degree"] for s in sections if s["n"])
    k = (degree + 1) ** 2
    out = {}
    for name in ("means", "scales", "rotations", "opacities"):
        out[name] = np.concatenate([s["want"][name] for s in sections])
    out["sh"] = np.concatenate([np.pad(s["want"]["sh"], ((0, 0), (0, k - s["want"]["sh"].shape[1]), (0, 0)))
                                for s in sections])
    return out


def assert_cloud(c, want, sh_atol=0.0):
    np.testing.assert_array_equal(c.means, want["means"])
    np.testing.assert_array_equal(c.scales, want["scales"])
    np.testing.assert_array_equal(c.rotations, want["rotations"])
    np.testing.assert_allclose(c.opacities, want["opacities"], rtol=1e-7)
    np.testing.assert_allclose(c.sh[:, :1], want["sh"][:, :1], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(c.sh[:, 1:], want["sh"][:, 1:], rtol=0, atol=sh_atol)


def file_of(level, seed):
    """Three sections of SH degree 2, 1 and 0 (the highest wins, lower ones zero-padded); level
    1/2 sections have full and partially filled buckets, one a non-default quantisation range and
    spare capacity."""
    rng = np.random.default_rng(seed)
    sections = [
        make_section(rng, 11, 2, level, full=2, partial=(3,)),
        make_section(rng, 7, 1, level, full=0, partial=(2, 5), quant_range=1000, capacity=9, block=2.5),
        make_section(rng, 4, 0, level, full=1),
    ]
    return sections, ksplat_bytes(sections, level, sh_range=(-1.5, 1.5) if level == 2 else (0.0, 0.0))


@pytest.mark.parametrize("level", [0, 1, 2])
def test_reads_files_built_from_the_layout(tmp_path, level):
    sections, data = file_of(level, level)
    path = tmp_path / "scene.ksplat"
    path.write_bytes(data)
    c = avsplat.read_ksplat(path)
    assert len(c) == 22 and c.sh_degree == 2
    assert_cloud(c, expected(sections), sh_atol=1e-6 if level == 2 else 0.0)
    # Detected by content when renamed; the name alone when it says .ksplat.
    renamed = tmp_path / "renamed.bin"
    renamed.write_bytes(data)
    assert avsplat.detect_gaussian_format(renamed).format == "ksplat"
    np.testing.assert_array_equal(avsplat.read_gaussians(renamed).means, c.means)


@pytest.mark.parametrize("level", [0, 1, 2])
@pytest.mark.parametrize("degree", [0, 1, 2])
def test_splat_transform_reads_our_test_files_as_we_do(tmp_path, splat_transform, level, degree):
    """splat-transform 3.7's .ksplat reader, through PLY, agrees with ours value by value (it
    stores log scales and logit opacities in the PLY: compared to float32 rounding). All sections
    have one SH degree, as GaussianSplats3D writes them: with sections of lower degree than the
    file's highest, splat-transform 3.7 puts their green and blue coefficients in the wrong
    columns, and the test of mixed degrees above holds ours to the layout instead."""
    rng = np.random.default_rng(10 * level + degree)
    # Capacity 12: sections of 4-byte multiples, as splat-transform's typed arrays need.
    sections = [make_section(rng, 11, degree, level, full=2, partial=(3,), capacity=12),
                make_section(rng, 7, degree, level, full=0, partial=(2, 5), quant_range=1000, capacity=12, block=2.5)]
    src = tmp_path / "scene.ksplat"
    src.write_bytes(ksplat_bytes(sections, level, sh_range=(-1.5, 1.5) if level == 2 else (0.0, 0.0)))
    splat_transform(src, tmp_path / "scene.ply")
    theirs = avsplat.read_ply(tmp_path / "scene.ply")
    ours = avsplat.read_ksplat(src)
    assert len(theirs) == len(ours) == 18 and theirs.sh_degree == ours.sh_degree == degree
    np.testing.assert_array_equal(theirs.means, ours.means)
    np.testing.assert_allclose(theirs.scales, ours.scales, rtol=2e-6)
    np.testing.assert_allclose(theirs.opacities, ours.opacities, atol=2e-6)
    np.testing.assert_allclose(theirs.sh, ours.sh, atol=2e-6)
    qa = theirs.rotations / np.linalg.norm(theirs.rotations, axis=1, keepdims=True)
    qb = ours.rotations / np.linalg.norm(ours.rotations, axis=1, keepdims=True)
    np.testing.assert_allclose(qa, qb, atol=1e-6)
    assert_cloud(ours, expected(sections), sh_atol=1e-6 if level == 2 else 0.0)


def test_damaged_files_name_the_file_and_the_field(tmp_path):
    rng = np.random.default_rng(5)
    sec = make_section(rng, 6, 1, 1, full=1, partial=(2,))
    good = ksplat_bytes([sec], 1)

    def case(name, data, pattern):
        path = tmp_path / name
        path.write_bytes(data)
        with pytest.raises(OSError, match=pattern):
            avsplat.read_ksplat(path)

    def patched(offset, fmt, *values, data=good):
        b = bytearray(data)
        struct.pack_into(fmt, b, offset, *values)
        return bytes(b)

    case("short.ksplat", good[:1000], r"short\.ksplat: header: the file is shorter than the 4096-byte header")
    case("version.ksplat", patched(0, "<BB", 1, 0), r"version\.ksplat: version: 1\.0 is not supported")
    case("level.ksplat", patched(20, "<H", 3), r"level\.ksplat: compressionLevel: 3 is not 0, 1 or 2")
    case("sections.ksplat", patched(4, "<I", 10 ** 6), r"sections\.ksplat: maxSectionCount: 1000000 section headers do not fit")
    case("degree.ksplat", patched(4096 + 40, "<H", 3), r"degree\.ksplat: sections\[0\]\.sphericalHarmonicsDegree: 3")
    case("cut.ksplat", good[:-10], r"cut\.ksplat: sections\[0\]\.maxSplatCount: the section's 6 records of 42 bytes")
    # A section claiming 4 billion Gaussians: refused against the file size, nothing allocated.
    case("claim.ksplat", patched(4096, "<II", 0xFFFFFFF0, 0xFFFFFFF0), r"claim\.ksplat: sections\[0\]\.maxSplatCount")
    case("capacity.ksplat", patched(4096, "<I", 7), r"capacity\.ksplat: sections\[0\]\.splatCount: 7 exceeds the section's capacity 6")
    case("count.ksplat", patched(16, "<I", 5), r"count\.ksplat: splatCount: the header says 5 Gaussians, the sections hold 6")
    case("buckets.ksplat", patched(4096 + 32, "<I", 5), r"buckets\.ksplat: sections\[0\]\.fullBucketCount: 5 full and 1 partial buckets exceed the 2 buckets")
    lengths_at = 4096 + 1024
    case("lengths.ksplat", patched(lengths_at, "<I", 1),
         r"lengths\.ksplat: sections\[0\]\.partiallyFilledBucketCount: the buckets hold 5 Gaussians, the section 6")
    case("block.ksplat", patched(4096 + 16, "<f", float("nan")), r"block\.ksplat: sections\[0\]\.bucketBlockSize: nan")
    # Without the .ksplat name, a damaged header is not taken for .ksplat at all.
    plain = tmp_path / "plain.bin"
    plain.write_bytes(patched(20, "<H", 3))
    with pytest.raises(OSError, match="not a Gaussian file this library knows"):
        avsplat.read_gaussians(plain)
    with pytest.raises(OSError, match=r"out\.ksplat: \.ksplat files cannot be written"):
        avsplat.write_gaussians(tmp_path / "out.ksplat", avsplat.read_ksplat(write(tmp_path / "ok.ksplat", good)))


def write(path, data):
    path.write_bytes(data)
    return path
