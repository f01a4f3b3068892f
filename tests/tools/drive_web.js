// Drive the browser image generator (`ttes web`) in headless Chromium with puppeteer-core (NODE_PATH: the
// npm folder of tests/tools/package.json). Prints one JSON object on stdout.
//   node drive_web.js keys URL OUT_DIR   standing screenshot, key "4" (PRONE), prone screenshot; key "x"
//                                        (ACTION CAM), its screenshot; keys "f" "w" (fly, forward); the states
//   node drive_web.js forces URL OUT_DIR a screenshot of a soldier of each force (DIS force 1, 2) from his
//                                        tethered camera (keys n, c): force-1.png, force-2.png; the states
//   node drive_web.js hidden URL OUT_DIR X,Y  soldier k moved to X+3k,Y, key "x" (ACTION CAM): hidden.png; the state
//   node drive_web.js reconnect URL      key 3, then (the caller restarts the server) bound again: the state
//   node drive_web.js fps URL SECONDS    the page's frames per second once every soldier is drawn
//                                        (SHOT=FILE.png: and a screenshot after the count)
//   node drive_web.js browser            start a browser for several drivers: prints its DevTools URL and
//                                        keeps it until stdin closes
// CHROMIUM: the browser (default /usr/bin/chromium). WebGL runs on SwiftShader (CPU), as on any headless box.
// BROWSER_WS: drive a page of that running browser (`browser` mode) instead of starting one. VIEWPORT: WxH of
// the page (default 800x600). TIMING=1: the phases' times on stderr.
const puppeteer = require("puppeteer-core");

const [mode, url, arg] = process.argv.slice(2);
const WAIT_MS = 120000;
const console_ = []; // the page's console and errors, printed when a wait fails
const T0 = Date.now();
const mark = (what) => { if (process.env.TIMING) console.error(`${((Date.now() - T0) / 1000).toFixed(2)} s ${what}`); };

const [W, H] = (process.env.VIEWPORT || "800x600").split("x").map(Number);
const viewport = { width: W, height: H };
const launch = () => puppeteer.launch({
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  headless: true,
  args: ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist",
    `--window-size=${W},${H}`],
  defaultViewport: viewport,
});

async function serveBrowser() {
  const browser = await launch();
  console.log(browser.wsEndpoint());
  process.stdin.resume();
  await new Promise((r) => process.stdin.on("end", r).on("close", r));
  await browser.close();
}

async function main() {
  if (mode === "browser") return serveBrowser();
  const shared = process.env.BROWSER_WS;
  const browser = shared ? await puppeteer.connect({ browserWSEndpoint: shared, defaultViewport: viewport }) : await launch();
  mark("browser up");
  let page = null;
  try {
    page = await browser.newPage();
    page.on("console", (m) => console_.push(`${m.type()}: ${m.text()}`));
    page.on("pageerror", (e) => console_.push(`pageerror: ${e.message}`));
    await page.goto(url, { waitUntil: "load" });
    mark("page loaded");
    // every soldier bound, drawn and posed from the wire
    await page.waitForFunction(() => window.ttes && ttes.ready && ttes.soldiers.length > 0
      && ttes.soldiers.filter((s) => s.index >= 0).every((s) => s.posed > 0), { timeout: WAIT_MS, polling: 200 });
    mark("soldiers posed");
    const state = () => page.evaluate(() => ({
      status: ttes.status, version: ttes.version, role: ttes.role, fps: ttes.fps, frames: ttes.frames,
      updates: ttes.updates, errors: ttes.errors, log: ttes.log,
      camera: ttes.camera(), current: ttes.current,
      soldiers: ttes.soldiers.map((s, k) => ({ index: s.index, appearance: s.appearance, rootZ: s.rootZ, force: s.force,
        colour: s.colour, box: ttes.screenBox(k) })),
    }));
    const frames = (n) => page.evaluate((k) => new Promise((r) => { // n more frames drawn
      const until = ttes.frames + k, poll = () => (ttes.frames >= until ? r() : requestAnimationFrame(poll)); poll();
    }), n);
    // at rest: soldier 0 got no new pose for half a second (an idle soldier costs no update, PROTOCOL.md §8.4)
    const settled = () => page.waitForFunction(() => {
      const s = ttes.soldiers[0], now = performance.now();
      if (s.posed !== s.seenPosed) { s.seenPosed = s.posed; s.seenAt = now; }
      return now - s.seenAt > 500;
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
      mark("settled");
      await page.screenshot({ path: `${arg}/standing.png` });
      mark("standing shot");
      const before = await state();
      await page.keyboard.press("4");
      await page.waitForFunction(() => ttes.soldiers[0].rootZ !== null && ttes.soldiers[0].rootZ < 0.4,
        { timeout: WAIT_MS, polling: 100 });
      mark("prone");
      await settled(); // lying still on the ground
      await page.screenshot({ path: `${arg}/prone.png` });
      mark("prone shot");
      const after = await state();
      await page.keyboard.press("x");
      await frames(2);
      await page.screenshot({ path: `${arg}/action.png` });
      const action = await state();
      await page.keyboard.press("f");
      await frames(1);
      const fly = await state();
      await page.keyboard.press("w");
      await frames(1);
      const forward = await state();
      await page.keyboard.press("v");
      const next = await state();
      await page.keyboard.press("?");
      const help = await page.evaluate(() => { const h = document.getElementById("help"); return h.hidden ? "" : h.textContent; });
      mark("views");
      console.log(JSON.stringify({ before, after, action, fly, forward, next, help, console: console_ }));
    } else if (mode === "hidden") {
      const xy = process.argv[5].split(",").map(Number);
      await page.evaluate(([x, y]) => ttes.soldiers.forEach((s, k) => ttes.place(k, [x + 3 * k, y])), xy);
      await page.keyboard.press("x");
      await frames(3);
      await page.screenshot({ path: `${arg}/hidden.png` });
      console.log(JSON.stringify({ hidden: await state(), console: console_ }));
    } else if (mode === "forces") {
      const shots = {};
      for (const force of [1, 2]) {
        await page.waitForFunction((f) => ttes.soldiers.some((s) => s.force === f && s.posed > 0), { timeout: WAIT_MS, polling: 200 }, force);
        while (await page.evaluate((f) => ttes.soldiers[ttes.current].force !== f, force)) await page.keyboard.press("n");
        await page.keyboard.press("c");
        await frames(3);
        await page.screenshot({ path: `${arg}/force-${force}.png` });
        shots[force] = await state();
      }
      const s = await state();
      console.log(JSON.stringify({ shots, soldiers: s.soldiers.length, updates: s.updates, errors: s.errors, console: console_ }));
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
    if (shared) { await page?.close(); await browser.disconnect(); } else await browser.close();
  }
}

main().catch((e) => { console.error(String(e && e.stack || e)); console.error(console_.join("\n")); process.exit(1); });
