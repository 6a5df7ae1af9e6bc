from setuptools import find_packages, setup

package_name = "objslam_mapper"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{package_name}"]),
        (f"share/{package_name}", ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="objslam maintainers",
    maintainer_email="maintainers@objslam.dev",
    description="ROS-free core of objslam (model, factor graph, association, map building) and the mapper node.",
    license="BSD-3-Clause",
    entry_points={"console_scripts": ["mapper = objslam_mapper.ros.node:main"]},
)
