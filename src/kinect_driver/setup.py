
from setuptools import find_packages, setup

package_name = 'kinect_driver'

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
    description='Kinect skeleton sources: OpenNI2/NiTE2 live tracking, bag/CSV replay and a synthetic sensor-model source.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'driver = kinect_driver.driver_node:main',
            'static_tf = kinect_driver.static_tf_node:main',
        ],
    },
)
