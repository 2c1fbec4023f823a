"""ament_python build of cbha_inverse: `colcon build` gives the `ros2 run` layout."""

from pathlib import Path

from setuptools import find_packages
from setuptools import setup

PACKAGE_NAME = 'cbha_inverse'
HERE = Path(__file__).resolve().parent


def tree_data_files(top):
    """List (install dir, [files]) pairs that mirror ``top`` under share/<package>/."""
    pairs = []
    if not (HERE / top).is_dir():
        return pairs
    for directory in sorted(p for p in (HERE / top).rglob('*') if p.is_dir()) + [HERE / top]:
        files = sorted(str(f.relative_to(HERE)) for f in directory.iterdir() if f.is_file())
        if files:
            pairs.append((f'share/{PACKAGE_NAME}/{directory.relative_to(HERE)}', files))
    return pairs


CONSOLE_SCRIPTS = [
    # nodes (node name = executable name = config/<name>.yaml)
    'trajectory = cbha_inverse.ros.nodes.trajectory:main',
    'inverse_solver = cbha_inverse.ros.nodes.inverse_solver:main',
    'shape_estimator = cbha_inverse.ros.nodes.shape_estimator:main',
    'cbha_sim = cbha_inverse.ros.nodes.cbha_sim:main',
    'stereo_tracker = cbha_inverse.ros.nodes.stereo_tracker:main',
    'cbha_excite = cbha_inverse.ros.nodes.cbha_excite:main',
    # commands
    'cbha_demo = cbha_inverse.experiments.demo:main',
    'condense_segment = cbha_inverse.fem.cli:main',
    'cbha_report = cbha_inverse.report.cli:main',
    'cbha_bench_core = cbha_inverse.report.bench_core:main',
    'cbha_bench_inverse = cbha_inverse.report.bench_inverse:main',
    'cbha_bench_estimator = cbha_inverse.report.bench_estimator:main',
    'cbha_fem_report = cbha_inverse.report.fem_report:main',
    'cbha_launch = cbha_inverse.ros.launch.launcher:main',
    'cbha_status = cbha_inverse.ros.console.status:main',
    'cbha_ctl = cbha_inverse.ros.console.ctl:main',
    'cbha_goto = cbha_inverse.ros.console.goto:main',
    'cbha_static_transform = cbha_inverse.ros.console.static_transform:main',
    'cbha_scene = cbha_inverse.scene.cli:main',
    'stereo_calibrate = cbha_inverse.vision.calibrate_cli:main',
    'cbha_bench_stereo = cbha_inverse.report.bench_stereo:main',
    'cbha_bench_node = cbha_inverse.report.bench_node:main',
    'robotino_bridge = cbha_inverse.ros.nodes.robotino_bridge:main',
    'fault_relay = cbha_inverse.ros.nodes.fault_relay:main',
    'inverse_solver_managed = cbha_inverse.ros.nodes.inverse_solver_managed:main',
    'robotino_bridge_managed = cbha_inverse.ros.nodes.robotino_bridge_managed:main',
    'cbha_build_robotino_msgs = cbha_inverse.interfaces.robotino_msgs_build:main',
    'cbha_build_tf2_msgs = cbha_inverse.interfaces.tf2_msgs_build:main',
    'cbha_bag = cbha_inverse.ros.bag.cli:main',
    'cbha_bench_bag = cbha_inverse.report.bench_bag:main',
    'cbha_identify = cbha_inverse.identify.cli:main',
    'cbha_identify_check = cbha_inverse.experiments.identify_check:main',
]

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE_NAME}']),
        (f'share/{PACKAGE_NAME}', ['package.xml']),
        *tree_data_files('config'),
        *tree_data_files('meshes'),
        *tree_data_files('launch'),
        *tree_data_files('rviz'),
    ],
    # the message packages PyPI lacks, built into the venv by make install
    # (cbha_inverse.interfaces.venv_install) or into a workspace by cbha_build_<package>
    package_data={'cbha_inverse.interfaces': [
        f'{package}/{pattern}' for package in ('robotino_msgs', 'tf2_msgs', 'control_msgs')
        for pattern in ('*.txt', '*.xml', 'LICENSE', 'msg/*.msg', 'action/*.action')]},
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='cbha_inverse maintainers',
    maintainer_email='maintainers@cbha-inverse.invalid',
    description='Quasi-static FEM inverse control of continuum robots with rigid vertebrae.',
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={'console_scripts': CONSOLE_SCRIPTS},
)
