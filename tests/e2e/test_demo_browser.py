"""End to end in a real headless browser (Debian's chromium + chromium-driver, offline): open the
page, pick a scene and a question, run an episode with the random policy, find the answer and the
video, save a screenshot; closing the page ends its browser session (the unload hook runs).

Never skipped: a missing browser fails with the command that installs it (tools/test.sh runs it)."""

from __future__ import annotations

import time

import pytest
from demo_helpers import start_demo, stop_demo
from torch_threads import one_torch_thread  # noqa: F401

from mqa_rl.demo.page_driver import BrowserMissing, DemoPage, chromium


def open_browser():
    """Debian's headless Chromium; a missing browser fails the test with the command that installs it."""
    try:
        return chromium()
    except BrowserMissing as error:
        pytest.fail(str(error))


@pytest.fixture(scope="module")
def served(small_dataset_dir, tmp_path_factory):
    mp = pytest.MonkeyPatch()
    mp.setenv("GRADIO_HEARTBEAT_INTERVAL", "1")       # a closed page is noticed within a second
    root = tmp_path_factory.mktemp("demo_browser")
    (root / "runs").mkdir()                            # no trained policy: the page must say so
    backend, demo, url = start_demo(small_dataset_dir, root / "runs", root / "cache", max_pushes=3, sessions=2)
    yield backend, url
    stop_demo(backend, demo)
    mp.undo()


@pytest.mark.timeout(300)
def test_pick_scene_and_question_run_and_read_the_answer_in_chromium(served, tmp_path):
    backend, url = served
    driver = open_browser()
    try:
        page = DemoPage(driver, url)
        assert page.open() == len(backend.dataset.scenes)
        assert "No trained policy" in driver.find_element("id", "status").text
        scene_id = page.pick_scene(1)
        assert scene_id == backend.catalog.select()[1].id
        text = page.pick_question(2)
        question = backend.questions.of_scene(scene_id, "counting")[2]
        assert text == question.text
        assert page.value("policy").startswith("random")
        shown = page.run()
        assert f"True answer: {question.answer}" in shown["answer"] and "no VQA checkpoint" in shown["answer"]
        assert question.id in shown["message"] and "done after" in shown["message"]
        assert shown["video_src"].endswith(".webm") and shown["video_seconds"] > 0      # the browser decoded it
        assert shown["frame_src"] and shown["table_rows"] >= 2
        assert page.screenshot(tmp_path / "demo.png").stat().st_size > 10_000
        assert any(backend.files.root.iterdir())                   # the session's video folder
    finally:
        driver.quit()
    deadline = time.time() + 30                                    # the page is gone: unload frees its files
    while any(backend.files.root.iterdir()) and time.time() < deadline:
        time.sleep(0.2)
    assert not any(backend.files.root.iterdir())
    assert backend.pool.free == backend.pool.size


class SlowPusher:
    """Pushes at the bin centre, one push every 2 s: an episode still running when its page closes."""

    def __init__(self):
        self.calls = 0

    def __call__(self, td):
        import torch

        from mqa_rl import keys
        from mqa_rl.envs import actions

        self.calls += 1
        time.sleep(2.0)
        td[keys.ACTION] = torch.tensor(actions.encode(0, 14, 14))
        return td


@pytest.mark.timeout(300)
def test_closing_the_page_mid_episode_frees_its_env(served, monkeypatch):
    from mqa_rl.demo.policies import PolicyEntry

    backend, url = served
    slow = SlowPusher()
    monkeypatch.setitem(backend.policies.entries, "random_masked", PolicyEntry("random_masked", actor=slow))
    driver = open_browser()
    try:
        page = DemoPage(driver, url)
        page.open()
        page.pick_policy("random_masked")
        driver.find_element("id", "run").click()
        page._present("#live-frame img")                          # the episode is under way
        assert backend.pool.borrowers
    finally:
        driver.quit()
    deadline = time.time() + 30
    while (backend.pool.free < backend.pool.size or backend.pool.borrowers) and time.time() < deadline:
        time.sleep(0.1)
    assert backend.pool.free == backend.pool.size and not backend.pool.borrowers
    assert slow.calls < backend.cfg.max_pushes                     # stopped, not played to its end
