import subprocess
import sys


def test_import_is_light():
    """`import mqa_rl` and `import mqa_rl.data` stay cheap for CLIs: no SAPIEN, torch or torchvision."""
    code = "import sys, mqa_rl, mqa_rl.data; print(sorted(m for m in ('sapien','torch','torchvision','torchrl') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "[]"
