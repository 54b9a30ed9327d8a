"""`uav-tilt` prints one JSON object per bench with the DESIGN section 7 keys."""
import json
import subprocess
import sys

from ros_graph import REPO


def test_bench_sim_prints_the_contract_keys():
    out = subprocess.run([sys.executable, '-m', 'uav_tilt_tools.cli', 'bench', 'sim',
                          '--seconds', '0.5'], cwd=REPO, capture_output=True, text=True,
                         timeout=300, check=True).stdout
    result = json.loads(out)
    for key in ('rtf_physics', 'rtf_camera', 'rtf_ros_lockstep'):
        assert result[key] > 0
