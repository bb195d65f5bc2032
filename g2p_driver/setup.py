from glob import glob

from setuptools import setup

package_name = "g2p_driver"

setup(
    name=package_name,
    version="0.1.0",
    packages=[package_name],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/launch", glob("launch/*.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="G2P rig maintainers",
    maintainer_email="g2p-rig@example.org",
    description="Raspberry Pi driver for the physical G2P rig, serving the rig contract.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "driver = g2p_driver.driver:main",
            "tendon_check = g2p_driver.tendon_check:main",
        ]
    },
)
