from glob import glob

from setuptools import find_packages, setup

package_name = 'kinect_bringup'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.xml')),
        ('share/' + package_name + '/config/presets', glob('config/presets/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='Kinect Posture Team',
    maintainer_email='robotics@example.com',
    description='Launch files, parameter files, the one-process pipeline and the user tools (demo, recorder, process_bag, recover_bag, calibrate_extrinsics).',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'pipeline = kinect_bringup.pipeline:main',
            'demo = kinect_bringup.demo:main',
            'recorder = kinect_bringup.recorder:main',
            'recover_bag = kinect_bringup.recover_bag:main',
            'process_bag = kinect_bringup.process_bag:main',
            'calibrate_extrinsics = kinect_bringup.calibrate_extrinsics:main',
        ],
    },
)
