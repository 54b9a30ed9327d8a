"""`uav-tilt bench` prints one JSON object with the DESIGN section 7 keys."""
import json
import subprocess
import sys

import pytest

from ros_graph import REPO

KEYS = {
    'sim': ('rtf_physics', 'rtf_camera', 'rtf_ros_lockstep', 'render_ms_p50_structures',
            'render_ms_p50_structures_tinyrenderer'),
    'control': ('tick_us_p50', 'tick_us_p99', 'realtime_rate_hz', 'realtime_jitter_ms_p99'),
    'graph': ('rtf', 'controller_rate_hz', 'vision_fps', 'vision_latency_ms_p95',
              'realtime_rtf', 'realtime_controller_rate_hz', 'realtime_jitter_ms_p99',
              'realtime_jitter_ms_p99_on_tick'),
}


@pytest.mark.alone     # speed measurements
@pytest.mark.parametrize('what', sorted(KEYS))
def test_bench_prints_the_contract_keys(what):
    # the graph's vision statistics need a few frames and a vision status in the window
    seconds = '3' if what == 'graph' else '1'
    out = subprocess.run([sys.executable, '-m', 'uav_tilt_tools.cli', 'bench', what,
                          '--seconds', seconds], cwd=REPO, capture_output=True, text=True,
                         timeout=300, check=True).stdout
    result = json.loads(out)
    for key in KEYS[what]:
        assert result[key] > 0, (key, result)
    if what == 'graph':
        assert set(result['cpu_s_per_sim_s']) == {'plant', 'controller', 'vision'}
        assert all(v > 0 for v in result['cpu_s_per_sim_s'].values())
        assert result['realtime_late_commands'] >= 0
        assert result['realtime_late_commands_on_tick'] >= 0
