// Opens a page in headless chromium (Playwright driving the given executable), waits until the
// avsplat viewer reports "ready" (or "error"), then writes a screenshot of the viewport.
//   NODE_PATH=<folder holding playwright-core> node browser_capture.cjs CHROMIUM URL WIDTH HEIGHT OUT.png
// Prints one JSON line: {"status": ..., "error": ..., "frames": ...}. Exits 1 on a page error.
const { chromium } = require("playwright-core");

async function main() {
  const [executablePath, url, width, height, out] = process.argv.slice(2);
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
