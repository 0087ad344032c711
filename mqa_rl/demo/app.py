"""The demo page (Gradio Blocks) over a ``DemoBackend``: gallery, question, policy, Run, answer.

Gradio is what ML demos are shared with; its queue streams a generator's yields to the page (one
frame per env step), runs at most ``sessions`` episodes at once (the env pool's size; later clicks
wait in its queue, with their position shown), cancels an episode whose page is closed or whose
Stop is pressed, and calls ``unload`` when a browser session ends. Every event has an API name, so
``gradio_client`` drives the same functions as the page (tests, benchmarks/demo_latency.py).
"""

from __future__ import annotations

import logging
import os

os.environ.setdefault("GRADIO_ANALYTICS_ENABLED", "False")    # a local demo: no telemetry, no version check

import gradio as gr  # noqa: E402
import pandas as pd  # noqa: E402

from mqa_rl.data.dataset import LEVELS, SPLITS  # noqa: E402
from mqa_rl.data.questions import QUESTION_TYPES  # noqa: E402
from mqa_rl.demo.backend import DemoBackend, EpisodeUpdate  # noqa: E402
from mqa_rl.demo.scenes import ALL  # noqa: E402

log = logging.getLogger(__name__)
INTRO = """# MQA: answering a question by pushing objects
Pick a scene (its first camera image), a question (or type one), a policy, and press **Run**: the
robot pushes objects in the bin live (each push drawn as a red arrow; for a Q-network its Q map
beside it, warm colours = high Q), the table shows how much of the question's targets is visible and
the reward terms of every step, and at the end the VQA answers from the first and last images."""
CACHE_LIFETIME = (600, 3600)     # (every, older than) seconds: Gradio's cached frames and videos are deleted
# system fonts only: the page must render offline (the default theme fetches web fonts)
THEME = gr.themes.Default(font=["ui-sans-serif", "system-ui", "sans-serif"],
                          font_mono=["ui-monospace", "monospace"])
# the renders are 224 px: show them large, pixels sharp
CSS = """
#scene-image img, #live-frame img { width: 100%; height: 100%; object-fit: contain; image-rendering: pixelated; }
"""


def _rows_frame(rows: list[dict], columns: list[str]) -> pd.DataFrame:
    return pd.DataFrame([{k: ("" if v is None else v) for k, v in row.items()} for row in rows], columns=columns)


def build_app(backend: DemoBackend) -> gr.Blocks:
    catalog, questions, policies = backend.catalog, backend.questions, backend.policies
    cards = catalog.select()
    first_scene = cards[0].id

    def gallery_items(selected):
        return [(str(c.image), c.short_caption) for c in selected]

    def question_choices(scene_id: str, qtype: str):
        choices = [(q.text, q.id) for q in questions.of_scene(scene_id, qtype)]
        return gr.Dropdown(choices=choices, value=choices[0][1] if choices else None)

    def filter_scenes(level: str, split: str):
        selected = catalog.select(level, split)
        return gallery_items(selected), [c.id for c in selected]

    def pick_scene(visible: list[str], evt: gr.SelectData):
        return visible[evt.index] if 0 <= evt.index < len(visible) else gr.skip()

    def show_scene(scene_id: str, qtype: str):
        card = catalog.card(scene_id)
        return str(card.image), question_choices(scene_id, qtype), f"{card.caption} · {card.objects} objects"

    def run(scene_id, question_id, typed, policy, vqa, seed, request: gr.Request):
        session = getattr(request, "session_hash", None) or "anonymous"
        first = True
        for u in backend.run_episode(scene_id, question_id, typed, policy, vqa, int(seed or 0), session):
            yield _outputs(u, first, session)
            first = False

    def _outputs(u: EpisodeUpdate, first: bool, session: str):
        frame = backend.frame_file(session, u.frame) if u.frame is not None else (None if first else gr.skip())
        table = _rows_frame(u.rows, backend.table_columns) if u.rows or first else gr.skip()
        if u.done:
            answer = u.answer if u.answer is not None else None
            answer_text, video = u.answer_text, (str(u.video) if u.video else None)
        elif first:
            answer, answer_text, video = None, "*running…*", None
        else:
            answer, answer_text, video = gr.skip(), gr.skip(), gr.skip()
        return frame, table, answer, answer_text, video, u.message

    def release(request: gr.Request):
        """The browser session ended (tab closed): its episode, if one runs, is cancelled by Gradio
        (which returns the env to the pool); its videos go."""
        if request is not None and request.session_hash:
            backend.release(request.session_hash)

    default_policy = backend.default_policy
    # the live frames and episode videos Gradio caches are deleted an hour after they were made
    with gr.Blocks(title="MQA demo", analytics_enabled=False, delete_cache=CACHE_LIFETIME) as demo:
        gr.Markdown(INTRO)
        gr.Markdown(backend.status(), elem_id="status")
        with gr.Row():
            with gr.Column(scale=3):
                with gr.Row():
                    level = gr.Radio([ALL, *LEVELS], value=ALL, label="level", elem_id="level")
                    split = gr.Radio([ALL, *SPLITS], value=ALL, label="split", elem_id="split")
                gallery = gr.Gallery(gallery_items(cards), label="scenes (first camera image)", columns=5, height=430,
                                     allow_preview=False, object_fit="contain", elem_id="scene-gallery")
            with gr.Column(scale=2):
                scene = gr.Dropdown([c.id for c in cards], value=first_scene, label="scene", elem_id="scene")
                scene_image = gr.Image(str(cards[0].image), label="first camera image", height=400,
                                       interactive=False, elem_id="scene-image")
                scene_info = gr.Markdown(f"{cards[0].caption} · {cards[0].objects} objects")
        with gr.Row():
            with gr.Column():
                qtype = gr.Radio(list(QUESTION_TYPES), value=QUESTION_TYPES[0], label="question type", elem_id="qtype")
                question = gr.Dropdown([(q.text, q.id) for q in questions.of_scene(first_scene, QUESTION_TYPES[0])],
                                       value=questions.of_scene(first_scene, QUESTION_TYPES[0])[0].id,
                                       label="question", elem_id="question",
                                       allow_custom_value=True)    # API callers pass any id; the backend checks it
                typed = gr.Textbox(label="or type a question (used when not empty)", elem_id="typed-question",
                                   placeholder="How many cans are there in the bin?")
            with gr.Column():
                policy = gr.Dropdown(policies.names, value=default_policy, label="policy", elem_id="policy")
                vqa = gr.Dropdown(backend.vqa.names, value=(backend.vqa.names or [None])[0], label="VQA checkpoint",
                                  elem_id="vqa", info=None if backend.vqa.names else "none usable: see above")
                seed = gr.Number(0, precision=0, label="seed (random policies)", elem_id="seed")
                with gr.Row():
                    run_button = gr.Button("Run", variant="primary", elem_id="run")
                    stop_button = gr.Button("Stop", elem_id="stop")
        message = gr.Markdown(elem_id="message")
        with gr.Row():
            with gr.Column(scale=3):
                gr.Markdown("**Live**: the state before each step with its push (red arrow), the state after "
                            "it, and for a Q-network its Q map (max over directions; white arrow: its best push)")
                live = gr.Image(show_label=False, format="jpeg", interactive=False, elem_id="live-frame")
            with gr.Column(scale=2):
                answer_text = gr.Markdown(elem_id="answer")
                answer = gr.Label(label="VQA answer probabilities", elem_id="answer-probs")
                video = gr.Video(label="episode video (download: the button on the player)", interactive=False,
                                 elem_id="episode-video")
        table = gr.Dataframe(_rows_frame([], backend.table_columns), interactive=False,
                             label="per step: the question's targets (how many, how many seen at all, their visible "
                                   "fraction A_s / A_t) and the step's reward terms",
                             elem_id="step-table")
        visible = gr.State([c.id for c in cards])

        for radio in (level, split):
            radio.change(filter_scenes, [level, split], [gallery, visible], api_name=False)
        gallery.select(pick_scene, [visible], scene, api_name=False)
        scene.change(show_scene, [scene, qtype], [scene_image, question, scene_info], api_name="scene")
        qtype.change(question_choices, [scene, qtype], question, api_name="questions")
        episode = run_button.click(run, [scene, question, typed, policy, vqa, seed],
                                   [live, table, answer, answer_text, video, message],
                                   api_name="run", concurrency_limit=backend.cfg.sessions, concurrency_id="episode")
        stop_button.click(None, cancels=[episode], api_name=False)
        demo.unload(release)
    return demo


def launch(backend: DemoBackend, host: str = "127.0.0.1", port: int | None = None, block: bool = True, **kwargs):
    """Serve the page on ``host:port`` (127.0.0.1: this machine only); returns the Blocks."""
    demo = build_app(backend)
    demo.queue(default_concurrency_limit=backend.cfg.sessions)
    demo.launch(server_name=host, server_port=port, prevent_thread_lock=not block, ssr_mode=False, theme=THEME, css=CSS,
                allowed_paths=[str(backend.catalog.directory), str(backend.files.root),
                               str(backend.frames.root)], show_error=True, **kwargs)
    return demo
