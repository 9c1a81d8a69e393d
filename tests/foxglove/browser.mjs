// Opens live.html in a headless Chromium (Debian's, driven by playwright-core) against a bridge,
// and prints what the page shows once it has shown `count` different values, as JSON.
//
//     node browser.mjs CHROMIUM URL TOPIC COUNT [SCREENSHOT.png]
import { chromium } from "playwright-core";
import { pathToFileURL } from "node:url";

const [executablePath, url, topic, count, screenshot] = process.argv.slice(2);
const browser = await chromium.launch({ executablePath, args: ["--no-sandbox"] });
try {
  const page = await browser.newPage();
  const page_url = new URL(pathToFileURL(new URL("live.html", import.meta.url).pathname));
  page_url.search = new URLSearchParams({ url, topic }).toString();
  await page.goto(page_url.href);
  const seen = [];
  while (new Set(seen).size < Number(count)) {
    const value = await page.textContent("#value");
    if (value !== "none" && seen[seen.length - 1] !== value) seen.push(value);
    await page.waitForTimeout(20);
  }
  const shown = {
    status: await page.textContent("#status"),
    schema: await page.textContent("#schema"),
    values: seen,
  };
  if (screenshot) await page.screenshot({ path: screenshot });
  process.stdout.write(JSON.stringify(shown) + "\n");
} finally {
  await browser.close();
}
