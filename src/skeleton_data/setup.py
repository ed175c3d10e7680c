from setuptools import find_packages, setup

package_name = 'skeleton_data'

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
    description='Offline data import: BVH/mocap clips, built-in motions, the motion database, UI-PRMD and Vicon readers.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'build_db = skeleton_data.database_cli:main',
            'import_azure_json = skeleton_data.k4abt:main',
        ],
    },
)
