from glob import glob

from setuptools import find_packages, setup

package_name = "objslam_common"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{package_name}"]),
        (f"share/{package_name}", ["package.xml"]),
        (f"share/{package_name}/config", glob("../../config/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="objslam maintainers",
    maintainer_email="maintainers@objslam.dev",
    description="What every objslam package shares: cameras, mount, class catalog, geometry, records, config, errors.",
    license="BSD-3-Clause",
)
