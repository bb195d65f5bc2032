from setuptools import setup

package_name = "g2p_ros"

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
        "The ROS 2 library shared by the G2P nodes: the rig contract, its server and client, message"
        " conversion, configuration as parameters, spinning and signals."
    ),
    license="Apache-2.0",
)
