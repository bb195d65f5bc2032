from glob import glob

from setuptools import setup

package_name = "g2p_bringup"

setup(
    name=package_name,
    version="0.1.0",
    packages=[package_name],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", [*glob("config/*.yaml"), *glob("config/*.xml")]),
        ("share/" + package_name + "/launch", glob("launch/*.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="G2P rig maintainers",
    maintainer_email="g2p-rig@example.org",
    description=(
        "Bring-up of the G2P graph: the graph description, the bringup executable, the launch file"
        " and the Fast DDS profiles."
    ),
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "bringup = g2p_bringup.bringup:main",
        ]
    },
)
