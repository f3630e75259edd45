"""The water stage: what the light travels through, at 532 nm.

Takes a water's absorption a and scattering b [1/m], group index and attenuation rule. Gives
:class:`~.properties.Water` with its beam attenuation c and the lidar attenuation k of each rule
(:mod:`.properties`), the phase functions with their sampling tables (:mod:`.phase`) and the small-angle
transmission that turns c into k at a receiver's footprint (:mod:`.smallangle`).
"""
