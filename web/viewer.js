// The page script of avsplat's web viewer (bundled with three.js and Spark by
// scripts/web_viewer.sh). It reads its configuration from the page (#avsplat-config, written by
// avsplat's viewer_page): the scene (embedded base64 bytes in #avsplat-scene, or a URL), the
// initial camera in avsplat's convention, the background and the render settings; it then draws
// the scene with Spark, the 3DGS conventions set so that the first frame matches avsplat's CPU
// renderer from the same camera. Dragging orbits around the camera's target (three.js
// OrbitControls). window.avsplatViewer.status becomes "ready" once the scene is loaded, sorted and
// drawn (the browser tests wait for it), or "error" with .error set; .idle is true whenever the
// last frame drawn is settled.
import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { SparkRenderer, SplatMesh } from "@sparkjsdev/spark";

const state = { status: "loading", error: null, frames: 0, idle: false };
window.avsplatViewer = state;
const statusLine = document.getElementById("avsplat-status");

function fail(error) {
  state.status = "error";
  state.error = String(error && error.message ? error.message : error);
  statusLine.textContent = "avsplat viewer: " + state.error;
  console.error(error);
}

function sceneBytes(config) {
  if (config.scene.url) {
    return fetch(config.scene.url).then((response) => {
      if (!response.ok) throw new Error(config.scene.url + ": HTTP " + response.status);
      return response.arrayBuffer().then((buffer) => new Uint8Array(buffer));
    });
  }
  const text = document.getElementById("avsplat-scene").textContent.replace(/\s+/g, "");
  const binary = atob(text);
  const bytes = new Uint8Array(binary.length);
  for (let i = 0; i < binary.length; ++i) bytes[i] = binary.charCodeAt(i);
  return Promise.resolve(bytes);
}

// avsplat's camera: world_to_camera (row-major 4 x 4, OpenCV axes: x right, y down, z forward)
// and pinhole intrinsics in pixels of a width x height image, pixel (0, 0) covering [0, 1)^2.
// three.js's camera looks along its -z with y up, so its pose is camera_to_world diag(1, -1, -1).
function poseFromAvsplat(camera) {
  const w2c = new THREE.Matrix4().fromArray(camera.world_to_camera.flat()).transpose();
  const c2w = w2c.clone().invert().multiply(new THREE.Matrix4().makeScale(1, -1, -1));
  const position = new THREE.Vector3();
  const quaternion = new THREE.Quaternion();
  const scale = new THREE.Vector3();
  c2w.decompose(position, quaternion, scale);
  return { position, quaternion };
}

// The OpenGL projection of the intrinsics, for a drawing area of width x height pixels: the
// camera's vertical field of view fills the area's height and the principal point keeps its
// offset from the centre, scaled alike (exact when the area has the camera's size).
function projectionFromAvsplat(camera, width, height) {
  const s = height / camera.height;
  const fx = camera.fx * s, fy = camera.fy * s;
  const cx = width / 2 + (camera.cx - camera.width / 2) * s;
  const cy = height / 2 + (camera.cy - camera.height / 2) * s;
  const n = camera.near, f = camera.far;
  return new THREE.Matrix4().set(
    (2 * fx) / width, 0, 1 - (2 * cx) / width, 0,
    0, (2 * fy) / height, (2 * cy) / height - 1, 0,
    0, 0, -(f + n) / (f - n), (-2 * f * n) / (f - n),
    0, 0, -1, 0);
}

async function main() {
  const config = JSON.parse(document.getElementById("avsplat-config").textContent);
  const canvas = document.getElementById("avsplat-canvas");
  // 3DGS colours are display values: Spark passes them through to an sRGB output (the default)
  // and the background is taken as given (no colour management).
  THREE.ColorManagement.enabled = false;
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false });
  renderer.outputColorSpace = THREE.SRGBColorSpace;
  renderer.setPixelRatio(window.devicePixelRatio);
  const [r, g, b] = config.background;
  renderer.setClearColor(new THREE.Color(r, g, b), 1);

  const scene = new THREE.Scene();
  const s = config.render;
  const spark = new SparkRenderer({
    renderer,
    preBlurAmount: s.low_pass,         // added to the 2D covariance, as 3DGS's 0.3
    blurAmount: 0,
    maxStdDev: s.extent_sigma,         // 3DGS's 3-sigma footprint
    minAlpha: s.alpha_threshold,       // 3DGS skips alpha < 1/255
    sortRadial: false,                 // 3DGS orders by view depth
    enableLod: false,
  });
  scene.add(spark);

  const cam = config.camera;
  const camera = new THREE.PerspectiveCamera(50, cam.width / cam.height, cam.near, cam.far);
  const pose = poseFromAvsplat(cam);
  camera.position.copy(pose.position);
  camera.quaternion.copy(pose.quaternion);
  camera.up.fromArray(config.up);

  function resize() {
    const width = canvas.clientWidth, height = canvas.clientHeight;
    renderer.setSize(width, height, false);
    camera.aspect = width / height;
    camera.projectionMatrix.copy(projectionFromAvsplat(cam, width, height));
    camera.projectionMatrixInverse.copy(camera.projectionMatrix).invert();
  }
  resize();
  window.addEventListener("resize", resize);

  // The controls would re-aim the camera at once (lookAt with `up`, losing any roll), so the
  // initial camera is kept exactly until the user first drags, zooms or pans.
  const controls = new OrbitControls(camera, canvas);
  controls.target.fromArray(config.target);
  camera.position.copy(pose.position);
  camera.quaternion.copy(pose.quaternion);
  let interacted = false;
  controls.addEventListener("start", () => { interacted = true; });

  const bytes = await sceneBytes(config);
  const mesh = new SplatMesh({ fileBytes: bytes, fileType: config.scene.type, extSplats: true });
  scene.add(mesh);
  await mesh.initialized;
  statusLine.textContent = "";
  statusLine.style.display = "none";

  // Frames are drawn on demand: while the depth order catches up with the camera (Spark sorts in
  // a worker), and again after each move; an idle page draws nothing.
  let settled = 0;
  let active = true;
  const wake = () => { active = true; settled = 0; state.idle = false; };
  controls.addEventListener("change", wake);
  window.addEventListener("resize", wake);
  renderer.setAnimationLoop(() => {
    if (!active) return;
    if (interacted) controls.update();
    renderer.render(scene, camera);
    state.frames += 1;
    settled = (!spark.sorting && !spark.sortDirty) ? settled + 1 : 0;
    if (settled >= 4) {
      active = false;
      state.idle = true;
      if (state.status === "loading") state.status = "ready";
    }
  });
}

main().catch(fail);
