"""A run's dashboards as a person opens them (tests/e2e/test_dashboards_browser.py, the screenshot in docs/figures): the
dashboard's own server started on a free port of 127.0.0.1 and stopped after, its page read in Debian's headless
Chromium (``mqa_rl.demo.page_driver.chromium``). Elements are found by the dashboards' own component names."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

from demo_helpers import free_port


def dashboard_command(kind: str, target: Path, port: int) -> list[str]:
    """The command a user types (docs/dashboards.md): TensorBoard over a folder of runs, or MLflow's UI over a store."""
    bin_dir = Path(sys.executable).parent
    if kind == "tensorboard":
        return [str(bin_dir / "tensorboard"), "--logdir", str(target), "--host", "127.0.0.1", "--port", str(port)]
    return [str(bin_dir / "mlflow"), "ui", "--backend-store-uri", f"sqlite:///{Path(target).resolve()}", "--workers", "1",
            "--host", "127.0.0.1", "--port", str(port)]


@contextlib.contextmanager
def serving(kind: str, target: Path, timeout: float = 180):
    """The dashboard server for the block; yields its URL once it answers. Its processes (a process group of their own)
    are stopped at the end, and the port is free again."""
    port = free_port()
    log = tempfile.NamedTemporaryFile("w+", suffix=f"-{kind}.log")
    server = subprocess.Popen(dashboard_command(kind, target, port), stdout=log, stderr=subprocess.STDOUT,
                              start_new_session=True)
    url = f"http://127.0.0.1:{port}/"
    try:
        deadline = time.time() + timeout
        while True:
            try:
                with urllib.request.urlopen(url + ("data/runs" if kind == "tensorboard" else "health"), timeout=5):
                    break
            except OSError:
                log.seek(0)
                if server.poll() is not None or time.time() > deadline:
                    raise RuntimeError(f"{kind} did not come up on {url}:\n{log.read()[-3000:]}") from None
                time.sleep(1)
        yield url
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        try:
            server.wait(30)
        except subprocess.TimeoutExpired:
            os.killpg(server.pid, signal.SIGKILL)
            server.wait()
        log.close()


class DashboardPage:
    """Selenium waits and lookups shared by both dashboards' pages."""

    def __init__(self, driver, url: str, timeout: float = 120):
        from selenium.common.exceptions import StaleElementReferenceException
        from selenium.webdriver.support.ui import WebDriverWait

        self.driver, self.url = driver, url
        # the pages re-render as their data arrives: an element read mid-render is looked up again
        self.wait = WebDriverWait(driver, timeout, ignored_exceptions=(StaleElementReferenceException,))

    def css(self, selector: str, within=None):
        from selenium.webdriver.common.by import By

        return (within or self.driver).find_elements(By.CSS_SELECTOR, selector)

    def filter(self, placeholder: str, text: str) -> None:
        from selenium.webdriver.common.keys import Keys

        box = self.wait.until(lambda _: self.css(f'input[placeholder="{placeholder}"]'))[0]
        box.send_keys(Keys.CONTROL, "a")             # typed over (clear() leaves a React input's value in place)
        box.send_keys(Keys.DELETE)
        box.send_keys(text)
        box.send_keys(Keys.ESCAPE)                   # the suggestions' list closed: it would cover the cards

    def loaded(self, img) -> bool:
        return bool(self.driver.execute_script("return arguments[0].complete && arguments[0].naturalWidth > 0", img))

    def screenshot(self, path: str | Path) -> Path:
        self.driver.save_screenshot(str(path))
        return Path(path)


class TensorBoardPage(DashboardPage):
    """TensorBoard's time series dashboard: runs on the left, a card per tag (scalar charts, images)."""

    def open(self) -> list[str]:
        """Load the page; returns the runs listed."""
        self.driver.get(self.url + "#timeseries")
        self.wait.until(lambda _: self.css("runs-selector") and "Run" in self.css("runs-selector")[0].text)
        return [line for line in self.css("runs-selector")[0].text.splitlines()[1:] if "/" in line]

    def show(self, tags: str) -> None:
        """Only the cards whose tag matches the regular expression ``tags``."""
        self.filter("Filter tags (regex)", tags)

    def scalar_card(self, tag: str):
        """The chart of ``tag`` once drawn: its text (title, legend: run, value, step)."""
        def drawn(_):
            for card in self.css("scalar-card"):
                if self.css(f'tb-truncated-path[title="{tag}"]', card) and self.css("canvas, svg.line-chart", card):
                    return card.text
            return False
        return self.wait.until(drawn)

    def image(self, tag: str):
        """The image card of ``tag`` once its image has loaded."""
        def shown(_):
            for card in self.css("image-card"):
                if self.css(f'tb-truncated-path[title="{tag}"]', card):
                    return next((img for img in self.css("img", card) if self.loaded(img)), False)
            return False
        return self.wait.until(shown)


class MLflowPage(DashboardPage):
    """MLflow's run page: its name in the header, a chart per metric and image key on 'Model metrics', the files
    under 'Artifacts'."""

    def open_run(self, experiment_id: str, run_id: str, name: str) -> None:
        self.driver.get(f"{self.url}#/experiments/{experiment_id}/runs/{run_id}/model-metrics")
        self.wait.until(lambda _: any(h.text == name for h in self.css("h1, h2, h3")))

    def cards(self):
        return self.css("[data-testid=experiment-view-compare-runs-card]")

    def chart(self, key: str) -> str:
        """The chart of metric ``key`` once drawn (a line, or a point for one step; its legend names the run and the
        key); returns its text."""
        self.filter("Search metric charts", key)
        return self.wait.until(lambda _: next((c.text for c in self.cards()
                                               if f"({key})" in c.text and self.css("path.js-line, path.point", c)), False))

    def image(self, key: str):
        """The image card of ``key`` once its image has loaded."""
        self.filter("Search metric charts", key)
        return self.wait.until(lambda _: next((img for c in self.cards() if key in c.text
                                               for img in self.css("img[src^='blob:']", c) if self.loaded(img)), False))

    def artifacts(self, experiment_id: str, run_id: str) -> list[str]:
        """The run's artifact folders and files listed on its 'Artifacts' tab."""
        self.driver.get(f"{self.url}#/experiments/{experiment_id}/runs/{run_id}/artifacts")
        self.wait.until(lambda _: "Select a file to preview" in self.driver.find_element("tag name", "body").text)
        return self.driver.find_element("tag name", "body").text.splitlines()
