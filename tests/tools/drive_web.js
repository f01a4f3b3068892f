// Drive the browser image generator (`ttes web`) in headless Chromium with puppeteer-core (NODE_PATH: the
// npm folder of tests/tools/package.json). Prints one JSON object on stdout.
//   node drive_web.js keys URL OUT_DIR   standing screenshot, key "4" (PRONE), prone screenshot, the state
//   node drive_web.js reconnect URL      key 3, then (the caller restarts the server) bound again: the state
//   node drive_web.js fps URL SECONDS    the page's frames per second once every soldier is drawn
//                                        (SHOT=FILE.png: and a screenshot after the count)
// CHROMIUM: the browser (default /usr/bin/chromium). WebGL runs on SwiftShader (CPU), as on any headless box.
const puppeteer = require("puppeteer-core");

const [mode, url, arg] = process.argv.slice(2);
const WAIT_MS = 120000;

async function main() {
  const browser = await puppeteer.launch({
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    headless: true,
    args: ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist",
      "--window-size=800,600"],
    defaultViewport: { width: 800, height: 600 },
  });
  const console_ = [];
  try {
    const page = await browser.newPage();
    page.on("console", (m) => console_.push(`${m.type()}: ${m.text()}`));
    page.on("pageerror", (e) => console_.push(`pageerror: ${e.message}`));
    await page.goto(url, { waitUntil: "load" });
    // every soldier bound, drawn and posed from the wire
    await page.waitForFunction(() => window.ttes && ttes.ready && ttes.soldiers.length > 0
      && ttes.soldiers.filter((s) => s.index >= 0).every((s) => s.posed > 0), { timeout: WAIT_MS, polling: 200 });
    const state = () => page.evaluate(() => ({
      status: ttes.status, version: ttes.version, role: ttes.role, fps: ttes.fps, frames: ttes.frames,
      updates: ttes.updates, errors: ttes.errors, log: ttes.log,
      soldiers: ttes.soldiers.map((s, k) => ({ index: s.index, appearance: s.appearance, rootZ: s.rootZ, box: ttes.screenBox(k) })),
    }));
    // at rest: soldier 0 got no new pose for a second (an idle soldier costs no update, PROTOCOL.md §8.4)
    const settled = () => page.waitForFunction(() => {
      const s = ttes.soldiers[0], now = performance.now();
      if (s.posed !== s.seenPosed) { s.seenPosed = s.posed; s.seenAt = now; }
      return now - s.seenAt > 1000;
    }, { timeout: WAIT_MS, polling: 100 });
    const bound = () => page.waitForFunction(() => ttes.accepted && ttes.soldiers.length > 0
      && ttes.soldiers.every((s) => s.index >= 0 && s.posed > 0), { timeout: WAIT_MS, polling: 200 });
    if (mode === "reconnect") { // soldier 0 kneels; the test restarts the server; the page binds them again
      await page.keyboard.press("3");
      console.log(JSON.stringify({ phase: "restart the server", before: await state() }));
      await page.waitForFunction(() => ttes.lost >= 1, { timeout: WAIT_MS, polling: 100 });
      await bound();
      await settled();
      console.log(JSON.stringify({ after: await state(), lost: await page.evaluate(() => ttes.lost), console: console_ }));
    } else if (mode === "keys") {
      await settled();
      await page.screenshot({ path: `${arg}/standing.png` });
      const before = await state();
      await page.keyboard.press("4");
      await page.waitForFunction(() => ttes.soldiers[0].rootZ !== null && ttes.soldiers[0].rootZ < 0.4,
        { timeout: WAIT_MS, polling: 100 });
      await settled(); // lying still on the ground
      await page.screenshot({ path: `${arg}/prone.png` });
      const after = await state();
      console.log(JSON.stringify({ before, after, console: console_ }));
    } else {
      const seconds = Number(arg || 5);
      await page.evaluate(() => new Promise((r) => setTimeout(r, 2000)));
      const t0 = await page.evaluate(() => [performance.now(), ttes.frames, ttes.updates]);
      await page.evaluate((s) => new Promise((r) => setTimeout(r, s * 1000)), seconds);
      const t1 = await page.evaluate(() => [performance.now(), ttes.frames, ttes.updates]);
      const dt = (t1[0] - t0[0]) / 1000;
      if (process.env.SHOT) await page.screenshot({ path: process.env.SHOT });
      const s = await state();
      console.log(JSON.stringify({ fps: (t1[1] - t0[1]) / dt, updates_per_s: (t1[2] - t0[2]) / dt, seconds: dt,
        soldiers: s.soldiers.length, errors: s.errors, console: console_ }));
    }
  } finally {
    await browser.close();
  }
}

main().catch((e) => { console.error(String(e && e.stack || e)); console.error(console_.join("\n")); process.exit(1); });
