from setuptools import setup

package_name = "g2p_recorder"

setup(
    name=package_name,
    version="0.1.0",
    packages=[package_name],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="G2P rig maintainers",
    maintainer_email="g2p-rig@example.org",
    description="Recording of the G2P graph to rosbag2 MCAP bags, and their replay: record and replay.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "record = g2p_recorder.record:main",
            "replay = g2p_recorder.replay:main",
        ]
    },
)
