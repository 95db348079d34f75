"""ament_python / pip set-up of cone_perception.

Installs the Python package, the node executables (``ros2 run cone_perception
<node>``), the ``cone-perception`` command, and ``calib/``, ``models/``,
``launch_configs/`` under ``share/cone_perception``.
"""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "cone_perception"


def share(pattern):
    return sorted(p for p in glob(pattern) if not p.endswith("/"))


setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["tests", "tests.*"]),
    package_data={PACKAGE: ["config/*.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/launch_configs", share("launch_configs/*.py") + share("launch_configs/*.yaml")
         + share("launch_configs/*.rviz")),
        (f"share/{PACKAGE}/calib", share("calib/*.yaml") + share("calib/*.md")),
        (f"share/{PACKAGE}/models", share("models/*.pt") + share("models/*.md") + share("models/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="cone_perception developers",
    maintainer_email="perception@example.org",
    description="Camera cone perception for a Formula Student driverless car (ROS 2).",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "cone-perception = cone_perception.cli:main",
            "driver_adapter = cone_perception.nodes.executables:driver_adapter",
            "mapping = cone_perception.nodes.executables:mapping",
            "detection = cone_perception.nodes.executables:detection",
            "pipeline = cone_perception.nodes.executables:pipeline",
            "cone_tracker = cone_perception.nodes.executables:cone_tracker",
        ],
    },
)
