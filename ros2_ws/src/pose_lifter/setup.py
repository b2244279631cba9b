"""pose_lifter: ament_python package (core + node + CLI); also installs with plain pip."""

from glob import glob

from setuptools import find_packages, setup

package_name = "pose_lifter"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "tests"]),
    package_data={"pose_lifter": ["py.typed", "data/*.npz", "msg/*.msg", "msg/hri_msgs/*.msg"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/viz", glob("viz/*.rviz") + glob("viz/*.json")),
    ],
    install_requires=["setuptools", "numpy", "scipy", "scikit-learn"],
    extras_require={"tools": ["rosbags", "tqdm", "matplotlib"], "reference": ["cvxpy", "clarabel", "scs"],
                    "fast": ["numba"],
                    # pose-lifter lift --scheduler: a collection of bags on a Dask cluster
                    "cluster": ["rosbags", "tqdm", "dask", "distributed"],
                    # training of the learned prior (tools/train_prior.py, tools/cross_action.py)
                    "train": ["torch==2.13.0"]},
    zip_safe=False,
    maintainer="pose_lifter maintainers",
    maintainer_email="pose-lifter@example.com",
    description="Robust 3D human pose lifting from 2D keypoints (Wang et al., CVPR 2014).",
    license="Apache-2.0",
    python_requires=">=3.10",
    entry_points={
        "console_scripts": [
            "lifter = pose_lifter.ros.entry:lifter",
            "adapter = pose_lifter.ros.entry:adapter",
            "lifter_lifecycle = pose_lifter.ros.entry:lifter_lifecycle",
            "pose-lifter = pose_lifter.cli:main",
            "action_recognition = pose_lifter.ros.entry:action_recognition",
        ],
    },
)
