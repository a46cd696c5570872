"""transform, sh_rotation and coordinate_system_change against references written here: a numpy
evaluation of the real SH basis (the 3DGS constants, written out independently of the C++),
the renderer (a moved scene seen from the moved camera), and splat-transform's own rotation."""

import numpy as np
import pytest

import avsplat


def sh_basis(d):
    """Real SH of degrees 0..3 at unit directions d (M, 3), the 3DGS / gsplat basis: (M, 16)."""
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    xx, yy, zz = x * x, y * y, z * z
    c1, c2, c3 = 0.4886025119029199, [1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
                                       -1.0925484305920792, 0.5462742152960396], \
        [-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
         -0.4570457994644658, 1.445305721320277, -0.5900435899266435]
    return np.stack([
        np.full_like(x, 0.28209479177387814),
        -c1 * y, c1 * z, -c1 * x,
        c2[0] * x * y, c2[1] * y * z, c2[2] * (2 * zz - xx - yy), c2[3] * x * z, c2[4] * (xx - yy),
        c3[0] * y * (3 * xx - yy), c3[1] * x * y * z, c3[2] * y * (4 * zz - xx - yy),
        c3[3] * z * (2 * zz - 3 * xx - 3 * yy), c3[4] * x * (4 * zz - xx - yy), c3[5] * z * (xx - yy),
        c3[6] * x * (xx - 3 * yy)], axis=1)


def random_rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]), q


def test_sh_rotation_against_numpy_brute_force():
    rng = np.random.default_rng(0)
    d = rng.normal(size=(200, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    for trial in range(6):
        A, q = random_rotation(rng)
        if trial % 2:
            A = A @ np.diag([1.0, -1.0, 1.0])  # a mirror: handedness changes
        for band in range(4):
            D = avsplat.sh_rotation(band, A)
            assert D.shape == (2 * band + 1, 2 * band + 1) and D.dtype == np.float64
            a = rng.normal(size=2 * band + 1)
            cols = slice(band * band, (band + 1) ** 2)
            lhs = sh_basis(d)[:, cols] @ (D @ a)
            rhs = sh_basis(d @ A)[:, cols] @ a  # rows of d @ A are A^T d
            np.testing.assert_allclose(lhs, rhs, atol=1e-12)
        if trial % 2 == 0:  # a quaternion gives the same matrices
            np.testing.assert_allclose(avsplat.sh_rotation(3, q), avsplat.sh_rotation(3, A), atol=1e-14)
    with pytest.raises(ValueError, match="orthogonal"):
        avsplat.sh_rotation(1, np.eye(3) * 2)


def test_transform_render_invariance_sh3():
    """A scene moved by (R, t, s) and seen from the camera moved the same way is the same image
    (SH degree 3, float64 rendering, to 1e-5)."""
    rng = np.random.default_rng(1)
    n = 400
    cloud = avsplat.GaussianCloud(rng.uniform(-0.6, 0.6, (n, 3)), rng.uniform(0.01, 0.06, (n, 3)),
                                  rng.normal(size=(n, 4)), rng.uniform(0.2, 0.9, n), rng.normal(size=(n, 16, 3)) * 0.5)
    cam = avsplat.Camera.look_at([0.4, -0.3, -2.5], [0, 0, 0], [0, -1, 0], 50, 96, 72)
    ref = avsplat.render(cloud, cam, precision="float64").color
    assert ref.max() > 0.2
    for s in (1.0, 0.3):
        R, _ = random_rotation(rng)
        t = np.array([1.0, -2.0, 0.5])
        moved = avsplat.transform(cloud, R, t, s)
        W = np.asarray(cam.world_to_camera)
        W2 = np.eye(4)
        W2[:3, :3] = W[:3, :3] @ R.T
        W2[:3, 3] = s * W[:3, 3] - W[:3, :3] @ R.T @ t
        cam2 = avsplat.Camera(cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height, W2, cam.near * s, cam.far * s)
        img = avsplat.render(moved, cam2, precision="float64").color
        assert np.abs(img - ref).max() < 1e-5
        # Geometry moved but colours not rotated: visibly different, so the check above can fail.
        wrong = avsplat.GaussianCloud(moved.means, moved.scales, moved.rotations, moved.opacities, cloud.sh)
        assert np.abs(avsplat.render(wrong, cam2, precision="float64").color - ref).max() > 1e-2


def test_transform_composition_inverse_and_errors():
    rng = np.random.default_rng(2)
    cloud = avsplat.GaussianCloud(rng.normal(size=(50, 3)), rng.uniform(0.1, 1, (50, 3)), rng.normal(size=(50, 4)),
                                  rng.uniform(0, 1, 50), rng.normal(size=(50, 9, 3)), confidence=rng.normal(size=50))
    A, _ = random_rotation(rng)
    t = np.array([0.1, 0.2, 0.3])
    moved = avsplat.transform(cloud, A, t, 2.0)
    np.testing.assert_allclose(moved.means, 2.0 * cloud.means @ A.T + t, atol=1e-5)
    np.testing.assert_allclose(moved.scales, 2.0 * cloud.scales, rtol=1e-7)
    np.testing.assert_array_equal(moved.confidence, cloud.confidence)
    back = avsplat.transform(moved, A.T, -A.T @ t / 2.0, 0.5)
    for f in ("means", "scales", "sh"):
        np.testing.assert_allclose(getattr(back, f), getattr(cloud, f), atol=2e-5, err_msg=f)
    # A quaternion's sign is free (q and -q are the same rotation): compare up to it.
    sign = np.sign(np.sum(back.rotations * cloud.rotations, axis=1))[:, None]
    np.testing.assert_allclose(back.rotations * sign, cloud.rotations, atol=2e-5)
    same = avsplat.transform(cloud)  # identity
    np.testing.assert_array_equal(same.means, cloud.means)
    with pytest.raises(ValueError, match="scale must be finite and > 0"):
        avsplat.transform(cloud, scale=-1.0)
    with pytest.raises(ValueError, match="rotation: expected shape"):
        avsplat.transform(cloud, np.eye(2))
    with pytest.raises(ValueError, match="not an orthogonal"):
        avsplat.transform(cloud, np.eye(3) * 1.5)


def test_coordinate_system_change():
    np.testing.assert_array_equal(avsplat.coordinate_system_change("RUB", "RDF"), np.diag([1.0, -1.0, -1.0]))
    np.testing.assert_array_equal(avsplat.coordinate_system_change("RDF", "RDF"), np.eye(3))
    assert np.linalg.det(avsplat.coordinate_system_change("RUB", "LUB")) == -1.0
    with pytest.raises(ValueError, match='"XYZ"'):
        avsplat.coordinate_system_change("XYZ", "RDF")


def euler_matrix(x, y, z):
    """R = Rz Ry Rx of angles in degrees (PlayCanvas's Quat.setFromEulerAngles, `--rotate x,y,z`)."""
    a, b, c = np.radians([x, y, z])
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    return rz @ ry @ rx


@pytest.mark.parametrize("degree", [1, 3])
def test_rotation_matches_splat_transform(tmp_path, splat_transform, degree):
    """splat-transform's -r x,y,z and avsplat's transform agree on means, rotations and SH: an
    independent implementation of the SH rotation. splat-transform rotates in PlayCanvas engine
    space, which is the PLY's turned 180 degrees about z, so in the file's coordinates its -r is
    F R F with F = diag(-1, -1, 1); that matrix goes to `avsplat convert --rotate` (9 values)."""
    import os
    import subprocess
    rng = np.random.default_rng(3)
    n = 300
    k = (degree + 1) ** 2
    cloud = avsplat.GaussianCloud(rng.normal(size=(n, 3)), rng.uniform(0.01, 0.2, (n, 3)), rng.normal(size=(n, 4)),
                                  rng.uniform(0.05, 0.95, n), rng.normal(size=(n, k, 3)) * 0.5)
    avsplat.write_ply(tmp_path / "in.ply", cloud)
    splat_transform(tmp_path / "in.ply", "-r", "30,-50,70", tmp_path / "st.ply")
    flip = np.diag([-1.0, -1.0, 1.0])
    R = flip @ euler_matrix(30, -50, 70) @ flip
    exe = os.path.join(os.path.dirname(avsplat.__file__), "..", "..", "apps", "avsplat")
    r = subprocess.run([exe, "convert", str(tmp_path / "in.ply"), str(tmp_path / "ours.ply"),
                        "--rotate", ",".join(repr(v) for v in R.ravel())], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    st, ours = avsplat.read_ply(tmp_path / "st.ply"), avsplat.read_ply(tmp_path / "ours.ply")
    np.testing.assert_allclose(ours.means, st.means, atol=1e-5)
    qa = ours.rotations / np.linalg.norm(ours.rotations, axis=1, keepdims=True)
    qb = st.rotations / np.linalg.norm(st.rotations, axis=1, keepdims=True)
    assert np.abs(np.abs(np.sum(qa * qb, axis=1)) - 1).max() < 1e-6
    np.testing.assert_allclose(ours.sh, st.sh, atol=1e-5)
    # The Python call gives the same cloud as the command line.
    py = avsplat.transform(cloud, R)
    np.testing.assert_array_equal(py.sh, ours.sh)
