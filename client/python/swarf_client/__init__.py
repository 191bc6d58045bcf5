"""swarf_client: a Python client of swarf, the NC milling simulation service.

    import numpy as np
    import swarf_client

    with swarf_client.Client("127.0.0.1:50051") as client:
        with client.create_session((0, 0, 100, 100, 0), spacing=0.5,
                                   tools={1: 3.0}, delete_on_exit=True) as s:
            s.send(np.array([[10, 50, 5], [10, 50, -2], [90, 50, -2]]))
            h = s.heights()          # h.z[j, i] at (h.x[i], h.y[j]), mm

Tools: a number is a ball-end radius; Ball, Flat, BullNose, Cone and
TaperedBall describe every cutter (radii and half angles, as the API).
The part as designed: s.set_design("part.stl") then s.deviation()
(gouge and excess, the moves that gouge). Arcs: s.send(tips,
arcs=[Arc(end, centre, clockwise=True)]), chorded by the server.
Programs: s.run_program("job.nc", tools={1: 1}) has the server interpret
the G-code (as `swarf run` does) and simulate it. Millimetres and degrees throughout; moves are tool-TIP positions. Errors
are SwarfError carrying the gRPC status code.
"""

from .client import (TILE_SIZE, Arc, Ball, BullNose, Client, Cone, Cutter,
                     DesignInfo, Deviation, DeviationMove, ErrorStats, Flat,
                     Heights, Jets, Mark, ProbeResult, ProgramResult,
                     SendResult, Session,
                     SwarfError, TaperedBall)

__all__ = ["Client", "Session", "SwarfError", "SendResult", "Heights",
           "Jets", "ErrorStats", "Mark", "ProbeResult", "TILE_SIZE", "Ball",
           "Flat", "BullNose", "Cone", "TaperedBall", "Cutter", "DesignInfo",
           "Deviation", "DeviationMove", "Arc", "ProgramResult"]
