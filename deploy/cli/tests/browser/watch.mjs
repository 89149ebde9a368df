// Opens the watch page of a run in Debian's Chromium and takes two screenshots a few seconds
// apart, once the page shows a first episode and again once it shows more, and (with `mark`)
// a restart or swap marked on its axes. Prints one JSON line: the episodes, the status text and
// the marks at each screenshot.
//   node watch.mjs URL FIRST.png SECOND.png [mark]
import { chromium } from "playwright-core";

const [url, first, second, mark] = process.argv.slice(2);
const browser = await chromium.launch({
  executablePath: process.env.ALFD_CHROMIUM || "/usr/bin/chromium",
  headless: true,
  args: ["--no-sandbox"],
});
try {
  const page = await browser.newPage({ viewport: { width: 1000, height: 620 } });
  await page.goto(url);
  const WAIT = { timeout: 120000, polling: 100 };
  const seen = async () => page.evaluate(() => ({
    episodes: Number(document.body.dataset.episodes),
    status: document.getElementById("status").textContent,
    paths: document.querySelectorAll("#returns path").length,
    marks: [...document.querySelectorAll("line.event")].length,
  }));
  await page.waitForFunction(() => Number(document.body.dataset.episodes) >= 2, null, WAIT);
  const a = await seen();
  await page.screenshot({ path: first });
  await page.waitForFunction(([n, mark]) => Number(document.body.dataset.episodes) >= n + 5 &&
    (!mark || document.querySelectorAll("line.event").length > 0), [a.episodes, mark], WAIT);
  await page.waitForTimeout(1500);
  const b = await seen();
  await page.screenshot({ path: second });
  console.log(JSON.stringify({ first: a, second: b }));
} finally {
  await browser.close();
}
