(R arcs, the long arc with negative R, a helix with P turns)
G21 G90
G0 X0 Y0 Z1
G1 Z0 F100
G2 X5 Y5 R5
G3 X0 Y0 R-5
G2 X0 Y0 Z-3 I2 J0 P3 (helix: three turns down)
G03 X2.5 Y2.5 R2.5 F50
G0 Z10
M30
