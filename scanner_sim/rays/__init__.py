"""The geometry stage: beam sub-rays cast into the scene (Embree behind one small interface), the receiver
check, the ``auto`` level's analytic seabed and collapsed echoes, and the hit record they all fill."""
