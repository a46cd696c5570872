// Opens a page in headless chromium (Playwright driving the given executable), waits until the
// avsplat viewer reports "ready" (or "error"), then writes a screenshot of the viewport.
//   NODE_PATH=<folder holding playwright-core> node browser_capture.cjs CHROMIUM URL WIDTH HEIGHT OUT.png [DRAG]
// With DRAG (pixels), the mouse then drags that far to the right from the centre, and the
// screenshot is taken once the viewer has settled again.
// Prints one JSON line: {"status": ..., "error": ..., "frames": ...}. Exits 1 on a page error.
const { chromium } = require("playwright-core");

async function main() {
  const [executablePath, url, width, height, out, drag] = process.argv.slice(2);
  const browser = await chromium.launch({
    executablePath,
    headless: true,
    // No GPU: WebGL2 through SwiftShader, software rendering on the CPU.
    args: ["--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
           "--ignore-gpu-blocklist", "--no-sandbox"],
  });
  try {
    const page = await browser.newPage({ viewport: { width: Number(width), height: Number(height) },
                                         deviceScaleFactor: 1 });
    const messages = [];
    page.on("console", (m) => messages.push(m.type() + ": " + m.text()));
    page.on("pageerror", (e) => messages.push("pageerror: " + e.message));
    await page.goto(url, { waitUntil: "load", timeout: 120000 });
    await page.waitForFunction(
      () => window.avsplatViewer && window.avsplatViewer.status !== "loading", null,
      { timeout: 240000, polling: 100 });
    if (drag) {
      const [x, y] = [Number(width) / 2, Number(height) / 2];
      await page.mouse.move(x, y);
      await page.mouse.down();
      await page.mouse.move(x + Number(drag), y, { steps: 5 });
      await page.mouse.up();
      await page.waitForFunction(() => window.avsplatViewer.idle, null, { timeout: 240000, polling: 100 });
    }
    const state = await page.evaluate(() => ({ ...window.avsplatViewer }));
    if (state.status === "ready") await page.screenshot({ path: out, type: "png", timeout: 240000 });
    state.messages = messages;
    console.log(JSON.stringify(state));
    return state.status === "ready" ? 0 : 1;
  } finally {
    await browser.close();
  }
}

main().then((code) => process.exit(code), (error) => { console.error(String(error)); process.exit(2); });
