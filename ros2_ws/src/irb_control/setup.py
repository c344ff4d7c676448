from glob import glob

from setuptools import find_packages, setup

package_name = 'irb_control'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml', 'README.md']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='IRB stack maintainers',
    maintainer_email='maintainers@irb-stack.dev',
    description=(
        'PD+ controller with friction compensation, simulator and axis-computer bridge '
        'for the IRB 1600.'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'simulator = irb_control.simulator_node:main',
            'pdplus = irb_control.pdplus_node:main',
            'axis_bridge = irb_control.axis_bridge_node:main',
            'fake_axis_computer = irb_control.fake_axis_computer_node:main',
        ],
    },
)
