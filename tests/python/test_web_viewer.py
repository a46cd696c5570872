"""The web viewer (avsplat.view, `avsplat view`, `avsplat convert SCENE out.html`) in a real
browser: Debian's chromium, headless (WebGL2 through SwiftShader), driven by Playwright
(browser_capture.cjs). Each page is loaded, the viewer's first frame is waited for and
screenshotted, and the screenshot is compared with avsplat's CPU renderer from the same camera
(PSNR over the foreground, the pixels the CPU render covers with alpha > 0.05). The same
comparison fails for pages made with a deliberately wrong convention (SH sign, up axis).

The viewer is installed on first use by scripts/web_viewer.sh into build-node/viewer (ignored);
the browser tests skip only when npm or chromium is absent, naming it.
"""
import base64
import html
import json
import os
import re
import shutil
import signal
import subprocess
import time
import urllib.error
import urllib.request

import numpy as np
import pytest

import avsplat

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CLI = os.path.join(ROOT, "build", "apps", "avsplat")
CAPTURE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "browser_capture.cjs")
REAL_SCENES = ["/work/shared/data/real/guitar.compressed.ply", "/work/shared/data/real/biker.spz"]
C0 = 0.28209479177387814
W, H = 320, 240


@pytest.fixture(scope="module")
def viewer_dir():
    """The installed viewer's folder (scripts/web_viewer.sh); skips without npm."""
    if shutil.which("npm") is None:
        pytest.skip("npm is not installed, so the web viewer (Spark) cannot be installed")
    done = subprocess.run(["bash", os.path.join(ROOT, "scripts", "web_viewer.sh")], capture_output=True, text=True)
    assert done.returncode == 0, "scripts/web_viewer.sh failed:\n" + done.stderr
    return done.stdout.strip().splitlines()[-1]


@pytest.fixture(scope="module")
def browser(viewer_dir):
    """capture(url, png, drag=None) -> H x W x 3 float image of the viewer's first settled frame,
    or, with drag, of the frame after dragging that many pixels to the right."""
    chromium = shutil.which("chromium")
    if chromium is None:
        pytest.skip("chromium is not installed (Debian package chromium), so no page can be rendered")
    node_modules = os.path.join(os.path.dirname(viewer_dir), "node_modules")

    def capture(url, out_png, drag=None):
        extra = [] if drag is None else [str(drag)]
        r = subprocess.run(["node", CAPTURE, chromium, url, str(W), str(H), str(out_png), *extra],
                           env={**os.environ, "NODE_PATH": node_modules}, capture_output=True, text=True,
                           timeout=600)
        assert r.returncode == 0, f"the page did not render ({r.returncode}):\n{r.stdout}\n{r.stderr}"
        import matplotlib.image

        return matplotlib.image.imread(str(out_png))[..., :3].astype(np.float64)

    return capture


def foreground_psnr(shot, cloud, camera):
    """PSNR of the screenshot against the CPU render, over the pixels the render covers."""
    ref = avsplat.render(cloud, camera)
    expected = np.round(np.clip(np.asarray(ref.color, np.float64), 0.0, 1.0) * 255.0) / 255.0
    mask = np.asarray(ref.alpha) > 0.05
    assert mask.mean() > 0.02, "the camera sees almost nothing of the scene"
    mse = np.mean((shot - expected)[mask] ** 2)
    psnr = 10.0 * np.log10(1.0 / max(mse, 1e-12))
    print(f"foreground PSNR {psnr:.2f} dB over {mask.sum()} pixels")  # the figure, with pytest -s
    return psnr


def sh1_scene():
    """2000 Gaussians of SH degree 1 in front of the identity camera whose colours stay inside
    [0, 1] from every direction: 0.3..0.7 from degree 0, at most 0.4886 * sqrt(3) * 0.25 = 0.22
    from degree 1 (Spark's colours above 1 differ from the CPU renderer's, which clamps only at 0)."""
    rng = np.random.default_rng(7)
    n = 2000
    z = rng.uniform(2.0, 6.0, n)
    means = np.stack([rng.uniform(-1, 1, n) * z * 0.5, rng.uniform(-1, 1, n) * z * 0.4, z], axis=1)
    scales = np.exp(rng.uniform(np.log(0.02), np.log(0.25), (n, 3)))
    quats = rng.normal(size=(n, 4))
    opacities = rng.uniform(0.2, 0.95, n)
    sh = np.zeros((n, 4, 3))
    sh[:, 0] = (rng.uniform(0.3, 0.7, (n, 3)) - 0.5) / C0
    sh[:, 1:] = rng.uniform(-0.25, 0.25, (n, 3, 3))
    return avsplat.GaussianCloud(means, scales, quats, opacities, sh)


def sh1_camera():
    return avsplat.Camera.look_at([0.4, -0.3, -0.5], [0.0, 0.0, 4.0], [0.0, -1.0, 0.0], 60.0, W, H)


@pytest.mark.parametrize("path", REAL_SCENES, ids=os.path.basename)
def test_html_of_a_real_scene_matches_the_cpu_renderer(browser, tmp_path, path):
    # SuperSplat scenes: a compressed PLY, and an SPZ (RUB axes, which the reader turns into ours).
    if not os.path.isfile(path):
        pytest.skip(f"{path} is not present")
    out = tmp_path / "scene.html"
    r = subprocess.run([CLI, "convert", path, str(out), "--size", f"{W}x{H}"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    cloud = avsplat.read_gaussians(path)
    camera = avsplat.default_camera(cloud, width=W, height=H)
    assert foreground_psnr(browser(out.as_uri(), tmp_path / "shot.png"), cloud, camera) >= 35.0


def test_html_of_sh_degree_1_matches_the_cpu_renderer(browser, tmp_path):
    cloud, camera = sh1_scene(), sh1_camera()
    out = tmp_path / "sh1.html"
    avsplat.write_html(out, cloud, camera)
    assert foreground_psnr(browser(out.as_uri(), tmp_path / "shot.png"), cloud, camera) >= 35.0


def test_comparison_fails_for_the_wrong_sh_sign(browser, tmp_path):
    # A viewer that evaluated degree 1 with the opposite sign shows the cloud with negated SH1.
    cloud, camera = sh1_scene(), sh1_camera()
    sh = np.asarray(cloud.sh).copy()
    sh[:, 1:] *= -1.0
    wrong = avsplat.GaussianCloud(cloud.means, cloud.scales, cloud.rotations, cloud.opacities, sh)
    out = tmp_path / "wrong_sign.html"
    avsplat.write_html(out, wrong, camera)
    # Far below the 35 dB that the right page passes (39.6 dB measured; this one 26.3 dB).
    assert foreground_psnr(browser(out.as_uri(), tmp_path / "shot.png"), cloud, camera) < 30.0


def test_comparison_fails_for_a_flipped_up_axis(browser, tmp_path):
    # A page whose camera had y up instead of avsplat's y down shows the scene upside down.
    cloud, camera = sh1_scene(), sh1_camera()
    flipped = avsplat.Camera(camera.fx, camera.fy, camera.cx, camera.cy, W, H,
                             np.diag([-1.0, -1.0, 1.0, 1.0]) @ np.asarray(camera.world_to_camera))
    out = tmp_path / "flipped.html"
    avsplat.write_html(out, cloud, flipped, up=(0.0, 1.0, 0.0))
    assert foreground_psnr(browser(out.as_uri(), tmp_path / "shot.png"), cloud, camera) < 20.0


def start_view(args, env=None):
    proc = subprocess.Popen([CLI, "view", *args, "--no-open"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)
    line = proc.stdout.readline()
    m = re.search(r"(http://127\.0\.0\.1:(\d+)/)", line)
    if not m:
        proc.kill()
        raise AssertionError(f"no URL in {line!r}: {proc.communicate()}")
    return proc, m.group(1)


def stop_view(proc):
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=10)
    return proc.returncode, out, err


def test_view_serves_the_page_and_the_scene_on_loopback_and_stops_on_ctrl_c(viewer_dir, tmp_path):
    cloud = sh1_scene()
    scene = tmp_path / "scene.ply"
    avsplat.write_ply(scene, cloud)
    proc, url = start_view([str(scene), "--size", f"{W}x{H}"])
    try:
        page = urllib.request.urlopen(url, timeout=30).read().decode()
        assert '"url":"scene.ply"' in page
        served = urllib.request.urlopen(url + "scene.ply", timeout=30).read()
        # The scene travels as write_ply's bytes of what was read.
        assert served == scene.read_bytes()
        with pytest.raises(urllib.error.HTTPError, match="404"):
            urllib.request.urlopen(url + "other", timeout=30)
    finally:
        code, out, err = stop_view(proc)
    assert code == 130, err  # 128 + SIGINT, as every command stopped by Ctrl-C
    assert "interrupted by SIGINT" in err


def test_view_page_renders_in_the_browser(browser, tmp_path):
    cloud, camera = sh1_scene(), sh1_camera()
    scene = tmp_path / "scene.ply"
    avsplat.write_ply(scene, cloud)
    eye = "0.4,-0.3,-0.5"
    proc, url = start_view([str(scene), "--eye", eye, "--target", "0,0,4", "--fov", "60", "--size", f"{W}x{H}"])
    try:
        shot = browser(url, tmp_path / "shot.png")
    finally:
        stop_view(proc)
    assert foreground_psnr(shot, cloud, camera) >= 35.0


def test_missing_viewer_says_how_to_install_it(tmp_path):
    cloud = sh1_scene()
    scene = tmp_path / "scene.ply"
    avsplat.write_ply(scene, cloud)
    env = {**os.environ, "AVSPLAT_WEB_VIEWER": str(tmp_path / "nowhere")}
    r = subprocess.run([CLI, "convert", str(scene), str(tmp_path / "x.html")], capture_output=True, text=True, env=env)
    assert r.returncode == 3
    assert "scripts/web_viewer.sh" in r.stderr and "nowhere" in r.stderr
    assert not (tmp_path / "x.html").exists()
    r = subprocess.run([CLI, "view", str(scene), "--no-open"], capture_output=True, text=True, env=env, timeout=30)
    assert r.returncode == 3 and "scripts/web_viewer.sh" in r.stderr
    assert avsplat.view.web_viewer_search_path() == avsplat.web_viewer_search_path()
    os.environ["AVSPLAT_WEB_VIEWER"] = str(tmp_path / "nowhere")
    try:
        assert avsplat.web_viewer_search_path() == [str(tmp_path / "nowhere")]
        with pytest.raises(avsplat.FileError, match="scripts/web_viewer.sh"):
            avsplat.find_web_viewer()
        with pytest.raises(avsplat.FileError, match="scripts/web_viewer.sh"):
            avsplat.write_html(tmp_path / "x.html", cloud)
    finally:
        del os.environ["AVSPLAT_WEB_VIEWER"]


def test_html_embeds_viewer_and_scene_and_needs_no_network(viewer_dir, tmp_path):
    cloud = sh1_scene()
    page = avsplat.web_viewer_page(cloud, sh1_camera(), title="a <scene>")
    assert "<title>a &lt;scene&gt;</title>" in page
    bundle = open(os.path.join(viewer_dir, "avsplat-viewer.js")).read()
    assert bundle in page
    # No address outside the page: nothing to fetch from a network.
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", page)
    embedded = re.search(r'id="avsplat-scene">([^<]*)<', page).group(1)
    ply = tmp_path / "scene.ply"
    avsplat.write_ply(ply, cloud)
    assert base64.b64decode(embedded) == ply.read_bytes()
    with pytest.raises(ValueError, match="background"):
        avsplat.web_viewer_page(cloud, sh1_camera(), background=(2.0, 0.0, 0.0))


def test_show_puts_the_page_in_an_iframe(viewer_dir):
    pytest.importorskip("IPython")
    cloud = sh1_scene()
    frame = avsplat.show(cloud, sh1_camera(), height=300)
    m = re.fullmatch(r'<div><iframe srcdoc="([^"]*)" style="width: 100%; height: 300px; border: 0" '
                     r'allowfullscreen></iframe></div>', frame.data)
    assert m, frame.data[:200]
    assert html.unescape(m.group(1)) == avsplat.web_viewer_page(cloud, sh1_camera())
    with pytest.raises(ValueError, match="height"):
        avsplat.view.show(cloud, height=0)


def fake_viewer(folder, template, bundle):
    folder.mkdir()
    (folder / "viewer.html").write_text(template)
    (folder / "avsplat-viewer.js").write_text(bundle)
    return str(folder)


def test_page_is_the_template_with_each_placeholder_filled_once(tmp_path):
    # Needs no npm: a stand-in viewer folder. What is put in is never searched for placeholders.
    template = ("<title>{{AVSPLAT_TITLE}}</title><script>{{AVSPLAT_CONFIG}}</script>"
                "<script>{{AVSPLAT_SCENE}}</script><script>{{AVSPLAT_BUNDLE}}</script>")
    bundle = 'const s = "{{AVSPLAT_SCENE}}";'
    folder = fake_viewer(tmp_path / "v", template, bundle)
    cloud = sh1_scene()
    page = avsplat.web_viewer_page(cloud, sh1_camera(), viewer_dir=folder, title="t")
    assert page.startswith("<title>t</title><script>{")
    assert page.endswith("<script>" + bundle + "</script>")
    assert page.count("{{AVSPLAT_SCENE}}") == 1  # the bundle's own text, untouched
    config = re.search(r"<script>(\{.*?\})</script>", page).group(1)
    config = json.loads(config)
    assert config["camera"]["world_to_camera"] == np.asarray(sh1_camera().world_to_camera).tolist()
    assert config["render"] == {"low_pass": pytest.approx(0.3), "extent_sigma": 3.0,
                                "alpha_threshold": pytest.approx(1 / 255)}
    # The default orbit target: the camera's axis point nearest to the robust bounds' centre.
    lo, hi = avsplat.robust_bounds(cloud)
    eye = np.array([0.4, -0.3, -0.5])
    forward = np.asarray(sh1_camera().world_to_camera)[2, :3]
    expected = eye + forward * np.dot((np.asarray(lo) + np.asarray(hi)) / 2 - eye, forward)
    np.testing.assert_allclose(config["target"], expected, atol=1e-9)

    bad = fake_viewer(tmp_path / "missing", template.replace("{{AVSPLAT_SCENE}}", ""), bundle)
    with pytest.raises(avsplat.FileError, match=r"viewer.html: must hold \{\{AVSPLAT_SCENE\}\} exactly once"):
        avsplat.web_viewer_page(cloud, viewer_dir=bad)
    closing = fake_viewer(tmp_path / "closing", template, 'x = "</script>";')
    with pytest.raises(avsplat.FileError, match="avsplat-viewer.js: contains"):
        avsplat.web_viewer_page(cloud, viewer_dir=closing)


def test_camera_options_of_html_output_are_checked(viewer_dir, tmp_path):
    scene = tmp_path / "scene.ply"
    avsplat.write_ply(scene, sh1_scene())
    # One initial view: an orbit is refused, and so are camera options for other outputs.
    r = subprocess.run([CLI, "convert", str(scene), str(tmp_path / "x.html"), "--orbit", "4"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "--orbit" in r.stderr and "one camera" in r.stderr
    r = subprocess.run([CLI, "convert", str(scene), str(tmp_path / "x.ply"), "--eye", "0,0,0"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and ".html output only" in r.stderr
    assert not (tmp_path / "x.html").exists() and not (tmp_path / "x.ply").exists()


def test_view_opens_the_browser_named_by_browser(viewer_dir, tmp_path):
    scene = tmp_path / "scene.ply"
    avsplat.write_ply(scene, sh1_scene())
    opened = tmp_path / "opened.txt"
    browser = tmp_path / "browser.sh"
    browser.write_text(f'#!/bin/sh\necho "$1" > {opened}\n')
    browser.chmod(0o755)
    proc = subprocess.Popen([CLI, "view", str(scene), "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "BROWSER": str(browser)})
    try:
        url = re.search(r"http://127\.0\.0\.1:\d+/", proc.stdout.readline()).group(0)
        for _ in range(100):  # the browser starts beside the server, without being waited for
            if opened.exists() and opened.read_text().strip():
                break
            time.sleep(0.1)
        assert opened.read_text().strip() == url
    finally:
        stop_view(proc)


def test_dragging_orbits_the_view(browser, tmp_path):
    cloud, camera = sh1_scene(), sh1_camera()
    out = tmp_path / "sh1.html"
    avsplat.write_html(out, cloud, camera)
    dragged = browser(out.as_uri(), tmp_path / "dragged.png", drag=80)
    # The view has turned: far from the initial frame, and not an empty image.
    assert foreground_psnr(dragged, cloud, camera) < 25.0
    assert dragged.mean() > 0.02
