from glob import glob

from setuptools import setup

package_name = "g2p_ros"

setup(
    name=package_name,
    version="0.1.0",
    packages=[package_name],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml") + glob("config/*.xml")),
        ("share/" + package_name + "/launch", glob("launch/*.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="G2P rig maintainers",
    maintainer_email="g2p-rig@example.org",
    description=(
        "ROS 2 parts shared by the G2P nodes (rig contract, parameters, message conversion, rig server)"
        " and the run tools: recorder, replay, report, bag recovery, bring-up."
    ),
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "record = g2p_ros.recorder_node:main",
            "replay = g2p_ros.replay_node:main",
            "report = g2p_ros.report_main:main",
            "recover_bag = g2p_ros.bag_recover_main:main",
            "bringup = g2p_ros.bringup_main:main",
        ]
    },
)
