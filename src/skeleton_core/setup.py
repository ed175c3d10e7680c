from setuptools import find_packages, setup

package_name = 'skeleton_core'

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
    description='Run-time core every node imports: skeleton model, geometry, conversions, CDR, bag I/O, filters, node helpers.',
    license='Apache-2.0',
)
