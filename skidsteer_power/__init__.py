"""skidsteer_power: locomotion power and energy of skid-steered robots on deformable terrain.

Physics after the FESS dissertation (shared/reference/fess-dissertation.txt): Bekker/Wong
terramechanics, Steeds / Wong / ICR skid-steering, the fast map model and FESS, plus the powertrain,
battery, DES 70/10 amplifier driver, ROS 2 nodes and bag tools around them. SI units everywhere.
"""

__version__ = '0.1.0'
