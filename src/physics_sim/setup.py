
from setuptools import find_packages, setup

package_name = 'physics_sim'

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
    description='MuJoCo physics character PD-tracking reconstructed postures (Shum & Ho 2012), with virtual joints, objects and pushes.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'physics = physics_sim.physics_node:main',
            'bench_physics = physics_sim.bench:main',
        ],
    },
)
