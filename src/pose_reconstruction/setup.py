
from setuptools import find_packages, setup

package_name = 'pose_reconstruction'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    tests_require=['pytest'],
    zip_safe=True,
    maintainer='Kinect Posture Team',
    maintainer_email='robotics@example.com',
    description='Posture reconstruction (Shum et al. 2013): per-joint reliability, database completion and the natural-posture-space optimizer.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'reliability = pose_reconstruction.reliability_node:main',
            'completion = pose_reconstruction.completion_node:main',
            'optimizer = pose_reconstruction.optimizer_node:main',
            'reconstruction = pose_reconstruction.reconstruction_node:main',
            'fusion = pose_reconstruction.fusion_node:main',
            'bench_reconstruction = pose_reconstruction.bench:main',
            'build_correction = pose_reconstruction.correction_build:main',
            'build_profile = pose_reconstruction.profile:main',
        ],
    },
)
