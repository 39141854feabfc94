// Loads KPL's view page in headless Chromium (Debian's `chromium`, driven by playwright-core),
// watches what it draws while a run goes, waits for a recognised situation of MONITOR in its
// list, clicks it, and keeps screenshots. Prints a JSON report: what was drawn when (per level:
// how many objects, and the valid time of the sample drawn), the situation, what was drawn after
// the click.
//
//     node tests/node/view_page.mjs URL OUT_DIR SECONDS MONITOR
//
// KPL_CHROMIUM names the browser (default /usr/bin/chromium).
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { chromium } from 'playwright-core';

const [url, outDir, seconds, monitor] = process.argv.slice(2);
const profile = mkdtempSync(join(tmpdir(), 'kpl-chromium-'));
const context = await chromium.launchPersistentContext(profile, {
  executablePath: process.env.KPL_CHROMIUM || '/usr/bin/chromium',
  headless: true,
  viewport: { width: 1400, height: 820 },
  args: ['--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run', '--disable-background-networking',
    '--disable-component-update', '--disable-sync'],
});
const report = { samples: [], situation: null, jumped: null, screenshots: [], errors: [] };
try {
  const page = await context.newPage();
  page.on('pageerror', (e) => report.errors.push(String(e)));
  await page.goto(url);
  const deadline = Date.now() + Number(seconds) * 1000;
  // What is drawn, every half second, until the situation is listed.
  while (Date.now() < deadline) {
    const drawn = await page.evaluate(() => {
      const v = window.kplView;
      if (!v || !v.drawn || v.drawn.t === null) return null;
      const frame = v.frame;
      return { t: v.drawn.t, levels: v.drawn.levels, valid: v.drawn.valid, situations: v.situations };
    });
    if (drawn) report.samples.push(drawn);
    const item = await page.$(`#situations li[data-monitor="${monitor}"]`);
    if (item && report.samples.length >= 5) break;
    await page.waitForTimeout(500);
  }
  const live = join(outDir, 'view-live.png');
  await page.screenshot({ path: live });
  report.screenshots.push(live);
  const item = await page.$(`#situations li[data-monitor="${monitor}"]`);
  if (item) {
    report.situation = { text: await item.innerText(), start: Number(await item.getAttribute('data-start')) };
    await item.click();
    await page.waitForFunction((start) => window.kplView.drawn && window.kplView.drawn.t === start, report.situation.start, { timeout: 10000 });
    // Zoom to the situation's objects.
    await page.evaluate(() => {
      const v = window.kplView;
      const marked = v.marked || [];
      if (marked.length) v.setView(marked[0][0], marked[0][1], 7);
    });
    await page.waitForTimeout(300);
    report.jumped = await page.evaluate(() => ({ t: window.kplView.drawn.t, levels: window.kplView.drawn.levels, valid: window.kplView.drawn.valid, marked: window.kplView.marked }));
    const zoomed = join(outDir, 'view-situation.png');
    await page.screenshot({ path: zoomed });
    report.screenshots.push(zoomed);
  }
} catch (e) {
  report.errors.push(String(e));
} finally {
  await context.close();
  rmSync(profile, { recursive: true, force: true });
}
console.log(JSON.stringify(report));
