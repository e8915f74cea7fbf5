"""LeRobot discovers the plugin with no flags, and `import lerobot_ocr` stays light."""

import subprocess
import sys


def _run(code: str) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_lerobot_auto_discovers_the_distribution():
    out = _run(
        "import sys, importlib.metadata as md\n"
        "from lerobot.utils.import_utils import register_third_party_plugins\n"
        "names = {d.metadata['Name'] for d in md.distributions()}\n"
        "assert 'lerobot_policy_ocr' in names, 'distribution name must keep underscores'\n"
        "assert 'lerobot_ocr' not in sys.modules\n"
        "register_third_party_plugins()\n"
        "print('lerobot_ocr' in sys.modules)\n"
    )
    assert out.strip() == "True"


def test_discover_packages_path_flag_loads_the_package():
    out = _run(
        "import sys\n"
        "from lerobot.configs.parser import load_plugin\n"
        "load_plugin('lerobot_ocr')\n"
        "print('lerobot_ocr' in sys.modules, 'lerobot_ocr.manifold' in sys.modules)\n"
    )
    assert out.split() == ["True", "True"]


def test_import_is_light():
    out = _run(
        "import sys, lerobot_ocr, lerobot_policy_ocr\n"
        "heavy = [m for m in ('robosuite', 'mujoco', 'gym_pusht', 'pymunk', 'pygame', 'matplotlib') if m in sys.modules]\n"
        "print(heavy)\n"
    )
    assert out.strip() == "[]"
