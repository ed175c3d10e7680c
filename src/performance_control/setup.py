from glob import glob

from setuptools import find_packages, setup

package_name = 'performance_control'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config/worlds', glob('config/worlds/*.yaml')),
    ],
    install_requires=['setuptools'],
    tests_require=['pytest'],
    zip_safe=True,
    maintainer='Kinect Posture Team',
    maintainer_email='robotics@example.com',
    description='Performance-based character control (Ishigaki et al. 2009): virtual features, '
                'intention recognition, intentional contacts, kinematic composition.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'control = performance_control.control_node:main',
            'bench_control = performance_control.bench:main',
            'demo_control = performance_control.demo:main',
        ],
    },
)
