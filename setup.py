"""ament_python package: builds with colcon on a ROS 2 Jazzy install, or with pip."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "rozyn_estimator"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*", "sim_node"]),
    package_data={PACKAGE: ["py.typed"], "sim_node": ["py.typed", "drive_cycles/*.csv"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
    ],
    # Runtime dependencies come from package.xml (rosdep) or requirements.txt (pip);
    # pinning them here would fight the ROS install.
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="rozyn_estimator maintainers",
    maintainer_email="maintainers@users.noreply.h-seed-f02815f4.example",
    description="Online vehicle inertial parameter estimation (Rozyn & Zhang) for ROS 2",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "rozyn = rozyn_estimator.tools.cli:main",
            "estimator_node = rozyn_estimator.tools.node_scripts:estimator_node",
            "sim_node = rozyn_estimator.tools.node_scripts:sim_node",
            "bag_recorder = rozyn_estimator.tools.node_scripts:bag_recorder",
        ],
    },
)
