"""ament_python package uav_tilt (DESIGN section 1)."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'uav_tilt'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(include=['uav_tilt_*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/config', glob('config/*.yaml')),
        ('share/' + PACKAGE + '/config/scenarios', glob('config/scenarios/*.yaml')),
        ('share/' + PACKAGE + '/config/meshes', glob('config/meshes/*.obj')),
        ('share/' + PACKAGE + '/config/plans', glob('config/plans/*.yaml')),
        # the detectors and their cards: vision_node's model_path is relative to these
        ('share/' + PACKAGE + '/models', sorted(glob('models/*.onnx') + glob('models/*.pt')
                                                + glob('models/*.json'))),
    ],
    install_requires=['setuptools'],
    # optional: `uav-tilt campaign --backend ray`, and the Gymnasium environment
    extras_require={'ray': ['ray>=2.9'], 'gym': ['gymnasium>=1.0']},
    zip_safe=True,
    maintainer='uav_tilt maintainers',
    description='Tilting-rotor H quadrotor for aerial contact inspection (ROS 2, PyBullet).',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'plant_node = uav_tilt_common.node_entry:plant',
            'controller_node = uav_tilt_common.node_entry:controller',
            'vision_node = uav_tilt_common.node_entry:vision',
            'recorder_node = uav_tilt_common.node_entry:recorder',
            'foxglove_bridge = uav_tilt_common.node_entry:foxglove',
            'uav-tilt = uav_tilt_tools.cli:main',
        ],
    },
)
