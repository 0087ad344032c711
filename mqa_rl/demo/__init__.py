"""The interactive web demo: pick a scene, ask a question, watch the robot push, read the answer.

``python recipes/demo.py`` serves it (Gradio, 127.0.0.1 by default). ``DemoBackend`` holds what the
page calls (env pool, scene images, policies, VQA), ``build_app`` / ``launch`` make the page.
Gradio is imported only by ``mqa_rl.demo.app`` (``pip install 'mqa_rl[demo]'``).
"""
