(I/J arcs, both directions, a full circle, G90.1 absolute centres)
G21 G90 G17
G0 X0 Y0 Z2
G1 Z-0.5 F200
G2 X10 Y0 I5 J0
G3 X0 Y0 I-5 J0
G2 X0 Y0 I3 J0 (full circle)
G90.1
G3 X4 Y4 I2 J2
G91.1
G0 Z5
M2
