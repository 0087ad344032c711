"""Drive the demo page in a real headless browser, as a person would (tests, the screenshot in docs/figures).

The browser is Debian's ``chromium`` with its ``chromium-driver`` (``tools/browser.sh`` installs
them); Selenium is pointed at both and never downloads a browser or driver (offline machines).
Elements are found by the ``elem_id``s of ``mqa_rl.demo.app``.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
INSTALL = "bash tools/browser.sh (as root: apt-get install -y chromium chromium-driver)"


class BrowserMissing(RuntimeError):
    """Debian's chromium or chromium-driver is not installed."""


def chromium(width: int = 1400, height: int = 2300):
    """A headless Chromium (Selenium WebDriver) with a ``width`` × ``height`` window."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    binary = shutil.which("chromium") or CHROMIUM
    driver = shutil.which("chromedriver") or CHROMEDRIVER
    missing = [p for p in (binary, driver) if not Path(p).exists()]
    if missing:
        raise BrowserMissing(f"{', '.join(missing)} not found: install Debian's headless browser with {INSTALL}")
    os.environ.setdefault("SE_OFFLINE", "true")              # Selenium Manager must not fetch anything
    options = webdriver.ChromeOptions()
    options.binary_location = binary
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
                "--disable-extensions", "--no-first-run", f"--window-size={width},{height}"):
        options.add_argument(arg)
    return webdriver.Chrome(service=Service(driver), options=options)


class DemoPage:
    """The demo page in ``driver``: pick a scene, a question and a policy, run, read the results."""

    def __init__(self, driver, url: str, timeout: float = 90):
        from selenium.webdriver.support.ui import WebDriverWait

        self.driver, self.url = driver, url
        self.wait = WebDriverWait(driver, timeout)

    def _css(self, selector: str):
        from selenium.webdriver.common.by import By

        return self.driver.find_elements(By.CSS_SELECTOR, selector)

    def _present(self, selector: str):
        from selenium.webdriver.common.by import By
        from selenium.webdriver.support import expected_conditions as ec

        return self.wait.until(ec.presence_of_element_located((By.CSS_SELECTOR, selector)))

    def open(self) -> int:
        """Load the page; returns the number of scene thumbnails shown."""
        self.driver.get(self.url)
        self._present("#scene-gallery button.thumbnail-item")
        return len(self._css("#scene-gallery button.thumbnail-item"))

    def value(self, elem_id: str) -> str:
        return self._css(f"#{elem_id} input")[0].get_attribute("value")

    def pick_scene(self, index: int) -> str:
        """Click the ``index``-th thumbnail; returns the scene id the page then shows."""
        before = self.value("scene")
        self._css("#scene-gallery button.thumbnail-item")[index].click()
        self.wait.until(lambda _: self.value("scene") != before)
        return self.value("scene")

    def _choose(self, elem_id: str, pick) -> str:
        self._css(f"#{elem_id} input")[0].click()
        self._present(f"#{elem_id} [role=option]")
        option = pick(self._css(f"#{elem_id} [role=option]"))
        text = option.get_attribute("aria-label")
        option.click()
        self.wait.until(lambda _: self.value(elem_id) == text)
        return text

    def pick_question(self, index: int) -> str:
        """Choose the ``index``-th question of the list; returns its text."""
        return self._choose("question", lambda options: options[index])

    def pick_policy(self, prefix: str) -> str:
        return self._choose("policy", lambda options: next(o for o in options if o.get_attribute("aria-label").startswith(prefix)))

    def run(self) -> dict:
        """Press Run and wait for the answer and the video; what the page then shows."""
        from selenium.webdriver.common.by import By
        from selenium.webdriver.support import expected_conditions as ec

        self._css("#run")[0].click()
        self.wait.until(ec.text_to_be_present_in_element((By.CSS_SELECTOR, "#answer"), "True answer"))
        video = self._present("#episode-video video")
        self.wait.until(lambda _: self.driver.execute_script("return arguments[0].readyState", video) >= 1)
        return {
            "answer": self._css("#answer")[0].text,
            "message": self._css("#message")[0].text,
            "video_src": video.get_attribute("src"),
            "video_seconds": self.driver.execute_script("return arguments[0].duration", video),
            "frame_src": self._present("#live-frame img").get_attribute("src"),
            "table_rows": int(self._css("#step-table [role=grid]")[0].get_attribute("aria-rowcount")) - 1,
        }

    def screenshot(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        self.driver.save_screenshot(str(path))
        return path
