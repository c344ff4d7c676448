from glob import glob

from setuptools import find_packages, setup

package_name = 'irb_description'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml', 'README.md']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.json')),
        ('share/' + package_name + '/urdf', glob('urdf/*.urdf')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='IRB stack maintainers',
    maintainer_email='maintainers@irb-stack.dev',
    description='URDF, dynamic parameters and the kinematics/dynamics model of the IRB 1600.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'model_check = irb_description.model_check:main',
            'generate_urdf = irb_description.generate_urdf:main',
            'kinematics_server = irb_description.kinematics_server:main',
            'state_publisher = irb_description.state_publisher:main',
        ],
    },
)
