from setuptools import setup

package_name = "g2p_viewer"

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
    description=(
        "The live view of a G2P run: a Foxglove WebSocket server showing the leg, the belt, the foot paths,"
        " the joint angles and every attempt, from the rig's topics and the learner's events, or from a bag."
    ),
    license="Apache-2.0",
    entry_points={"console_scripts": ["view = g2p_viewer.view:main"]},
)
