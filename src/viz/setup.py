from glob import glob

from setuptools import find_packages, setup

package_name = 'viz'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/rviz', glob('rviz/*.rviz') + glob('rviz/*.json')),
    ],
    install_requires=['setuptools'],
    tests_require=['pytest'],
    zip_safe=True,
    maintainer='Kinect Posture Team',
    maintainer_email='robotics@example.com',
    description='RViz markers for raw, reconstructed and simulated skeletons, and the offline demo report.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'viz = viz.viz_node:main',
            'hri = viz.hri_node:main',
            'bench_hri = viz.bench_hri:main',
            'report = viz.report:main',
        ],
    },
)
