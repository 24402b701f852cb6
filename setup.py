"""ament_python package ``lightfast``: the core library, the node packages and the ``lightfast`` CLI.

On a real ROS 2 Jazzy install, ``colcon build`` puts the console scripts into ``lib/lightfast`` (setup.cfg), so
``ros2 run lightfast <node>`` works; here ``scripts/setup.sh`` installs the same entry points into the venv.
"""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "lightfast"
# node packages, one per capability, added when each is built
NODES: list[str] = ["sun_update_node", "daylight_relight_node", "rgbd_tracker_node", "vtr_localizer_node",
                     "racr_node", "racr_platform_sim_node", "racr_vse_node"]

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*", *NODES]),
    package_data={f"{PACKAGE}.ros": ["*.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", sorted(glob("config/*.yaml"))),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="lightfast developers",
    description="Camera localization under changing daylight: ROS 2 Jazzy nodes, bag tools, simulators.",
    license="BSD-3-Clause",
    python_requires=">=3.10",
    entry_points={
        "console_scripts": [
            f"{PACKAGE} = {PACKAGE}.cli:main",
            *[f"{node} = {node}.node:main" for node in NODES],
        ],
    },
)
