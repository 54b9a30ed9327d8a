"""foxglove_bridge: a WebSocket client on 127.0.0.1 sees the channels advertised and data
flowing; without foxglove-sdk the node steps aside with exit code 0."""
import base64
import json
import os
import re
import socket
import struct
import subprocess
import sys
import time

import pytest

from ros_graph import REPO, start, stop

EXPECTED = {'/uav/camera': 'foxglove.RawImage', '/uav/scene': 'foxglove.SceneUpdate',
            '/uav/tf': 'foxglove.FrameTransforms', '/uav/force': None, '/uav/tilt': None,
            '/uav/mode': None}


class WebSocket:
    """The least client the Foxglove protocol needs: handshake, read frames, send text."""

    def __init__(self, port):
        self.sock = socket.create_connection(('127.0.0.1', port), timeout=10.0)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((
            f'GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n'
            f'Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n'
            'Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n').encode())
        self.buffer = b''
        while b'\r\n\r\n' not in self.buffer:
            self.buffer += self._recv()
        head, self.buffer = self.buffer.split(b'\r\n\r\n', 1)
        self.status_line = head.split(b'\r\n')[0].decode()

    def _recv(self):
        data = self.sock.recv(65536)
        if not data:
            raise ConnectionError('server closed the connection')
        return data

    def _take(self, n):
        while len(self.buffer) < n:
            self.buffer += self._recv()
        out, self.buffer = self.buffer[:n], self.buffer[n:]
        return out

    def read(self):
        """(opcode, payload) of the next frame (the server does not mask)."""
        b0, b1 = self._take(2)
        length = b1 & 0x7F
        if length == 126:
            length = struct.unpack('>H', self._take(2))[0]
        elif length == 127:
            length = struct.unpack('>Q', self._take(8))[0]
        return b0 & 0x0F, self._take(length)

    def send_text(self, text):
        payload, mask = text.encode(), os.urandom(4)
        header = bytes([0x81, 0x80 | 126]) + struct.pack('>H', len(payload)) \
            if len(payload) >= 126 else bytes([0x81, 0x80 | len(payload)])
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        self.sock.sendall(header + mask + masked)

    def close(self):
        self.sock.close()


def test_bridge_advertises_and_streams_the_channels(tmp_path):
    pytest.importorskip('foxglove')
    plant = start('uav_tilt_sim.plant_node', log_path=tmp_path / 'plant.log')
    log_path = tmp_path / 'foxglove.log'
    bridge = start('uav_tilt_tools.graph.foxglove_bridge', log_path=log_path,
                   params={'port': 0, 'use_sim_time': 'true'})
    client = None
    try:
        deadline = time.monotonic() + 60.0
        while not (found := re.search(r'ws://127\.0\.0\.1:(\d+)', log_path.read_text())):
            assert time.monotonic() < deadline and bridge.poll() is None, log_path.read_text()
            time.sleep(0.2)
        client = WebSocket(int(found.group(1)))
        assert client.status_line.startswith('HTTP/1.1 101'), client.status_line
        channels = {}
        while not EXPECTED.keys() <= channels.keys():
            opcode, payload = client.read()
            if opcode == 1 and (msg := json.loads(payload))['op'] == 'advertise':
                channels.update({c['topic']: c for c in msg['channels']})
        for topic, schema in EXPECTED.items():
            assert schema is None or channels[topic]['schemaName'] == schema
        assert channels['/uav/force']['encoding'] == 'json'
        client.send_text(json.dumps({'op': 'subscribe', 'subscriptions': [
            {'id': 7, 'channelId': channels['/uav/tf']['id']}]}))
        # A binary frame starting 0x01 is a message of a subscription: tf flows.
        opcode, payload = client.read()
        while not (opcode == 2 and payload[0] == 0x01):
            opcode, payload = client.read()
        assert struct.unpack('<I', payload[1:5])[0] == 7
    finally:
        if client:
            client.close()
        code, _ = stop(bridge)
        stop(plant)
    assert code == 0, log_path.read_text()


def test_without_foxglove_sdk_the_node_exits_0_with_one_line():
    script = ('import sys; sys.modules["foxglove"] = None\n'
              'from uav_tilt_tools.graph.foxglove_bridge import main\n'
              'sys.exit(main())')
    result = subprocess.run([sys.executable, '-c', script], cwd=REPO, capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 0
    assert [line for line in result.stderr.splitlines() if 'foxglove' in line] == [
        '[foxglove] foxglove-sdk is not installed (pip install foxglove-sdk): no live view']


def test_a_port_in_use_is_one_line_and_exit_2(tmp_path):
    pytest.importorskip('foxglove')
    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = subprocess.run([sys.executable, '-m', 'uav_tilt_tools.graph.foxglove_bridge',
                                 '--ros-args', '-p', f'port:={port}'], cwd=REPO,
                                capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and 'Traceback' not in result.stderr, result.stderr
    fatal = [line for line in result.stderr.splitlines() if 'FATAL' in line]
    assert len(fatal) == 1 and f"'port' = {port}" in fatal[0], result.stderr
