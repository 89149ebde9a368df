// Drives Debian's Chromium over the human expert's page, as a person would: for each step
// (`decline`, `click:N`, `key:NAME`) it waits for a new query on the page, notes what the page
// shows, and decides. The first query's page is saved as a PNG when a path is given ("-": none).
// Prints one JSON line: what was seen, and the page after the last decision.
//   node drive.mjs URL SCREENSHOT STEP...
import { chromium } from "playwright-core";

const [url, shot, ...steps] = process.argv.slice(2);
const browser = await chromium.launch({
  executablePath: process.env.ALFD_CHROMIUM || "/usr/bin/chromium",
  headless: true,
  args: ["--no-sandbox"],
});
try {
  const page = await browser.newPage({ viewport: { width: 720, height: 600 } });
  await page.goto(url);
  const seen = [];
  let last = 0;
  const WAIT = { timeout: 120000, polling: 50 };
  for (const step of steps) {
    await page.waitForFunction(
      (last) => typeof state !== "undefined" && state && state.active && state.query &&
        state.query.id > last && !document.getElementById("decline").disabled,
      last, WAIT);
    const s = await page.evaluate(() => ({
      id: state.query.id,
      state: state.query.state,
      budget: document.getElementById("budget").textContent,
      waiting: document.getElementById("waiting").textContent,
      status: document.getElementById("status").textContent,
      pole: !!document.getElementById("pole"),
      agent: !!document.getElementById("agent"),
      buttons: [...document.querySelectorAll("#actions button")].map((b) => b.textContent),
    }));
    if (shot && shot !== "-" && seen.length === 0) await page.screenshot({ path: shot });
    if (step === "decline") {
      await page.click("#decline");
    } else if (step.startsWith("click:")) {
      await page.click(`#actions button[data-action="${step.slice(6)}"]`);
    } else if (step.startsWith("key:")) {
      await page.keyboard.press(step.slice(4));
    } else {
      throw new Error(`unknown step ${step}`);
    }
    seen.push({ step, ...s });
    last = s.id;
  }
  await page.waitForFunction((last) => !state.query || state.query.id !== last, last, WAIT);
  const after = await page.evaluate(() => ({
    budget: document.getElementById("budget").textContent,
    demos: document.getElementById("demos").textContent,
    answered: state.answered,
    declined: state.declined,
  }));
  console.log(JSON.stringify({ seen, after }));
} finally {
  await browser.close();
}
