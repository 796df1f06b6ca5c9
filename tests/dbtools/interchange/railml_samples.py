"""Small hand-written railML documents with hand-computed expectations.

``RAILML24``: one 3 km track (line L1), trackBegin km 1000 rising, a mileage change at pos
1500 (km 2500 → 2600: a 100 m gap), trackEnd km 4100. Coordinates every 500 m on a
straight line due east at 60° N (1 m = 1/(111 319.49·cos 60°) deg of longitude, close
enough for the test's 1 m tolerance). Radius changes: straight from pos 0 (a radiusChange
holds until the next one; before the first one nothing is known), a left curve — clothoid
pos 400–460, arc R 600 m 460–700, clothoid 700–760 — and straight to the end. Balises: an
initial pair at pos 1100/1105, a C balise at 1800
with a home signal 50 m ahead, a lone balise at 2900.
"""

from __future__ import annotations

import math

LAT = 60.0
LON0 = 25.0
M_PER_DEG_LON = 111_319.49 * math.cos(math.radians(LAT))


def lon_at(pos: float) -> float:
    return LON0 + pos / M_PER_DEG_LON


def _geo(pos: float) -> str:
    return f'<geoCoord coord="{LAT} {lon_at(pos)!r}" epsgCode="urn:ogc:def:crs:EPSG::4326"/>'


RAILML24 = f"""<?xml version="1.0" encoding="UTF-8"?>
<railml xmlns="https://www.railml.org/schemas/2018" version="2.4">
  <infrastructure id="is1">
    <tracks>
      <track id="T1" name="track one">
        <trackTopology>
          <trackBegin id="tb1" pos="0" absPos="1000" absDir="raising">{_geo(0)}</trackBegin>
          <trackEnd id="te1" pos="3000" absPos="4100">{_geo(3000)}</trackEnd>
          <mileageChanges>
            <mileageChange id="mc1" pos="1500" absPosIn="2500" absPos="2600" type="gap">{_geo(1500)}</mileageChange>
          </mileageChanges>
        </trackTopology>
        <trackElements>
          <radiusChanges>
            <radiusChange id="rc0" pos="0" radius="0"/>
            <radiusChange id="rc1" pos="400" radius="-600" geometryElementDescription="clothoid"/>
            <radiusChange id="rc2" pos="460" radius="-600"/>
            <radiusChange id="rc3" pos="700" radius="-600" geometryElementDescription="clothoid"/>
            <radiusChange id="rc4" pos="760" radius="0"/>
          </radiusChanges>
          <geoMappings>
            <geoMapping id="gm500" pos="500">{_geo(500)}</geoMapping>
            <geoMapping id="gm1000" pos="1000">{_geo(1000)}</geoMapping>
            <geoMapping id="gm2000" pos="2000">{_geo(2000)}</geoMapping>
            <geoMapping id="gm2500" pos="2500">{_geo(2500)}</geoMapping>
          </geoMappings>
          <speedChanges>
            <speedChange id="sc1" pos="100" dir="up" vMax="120"/>
          </speedChanges>
        </trackElements>
        <ocsElements>
          <signals>
            <signal id="sig1" pos="1850" dir="up" type="main" function="home" name="H1"/>
          </signals>
          <balises>
            <balise id="b_i1" pos="1100" dir="up" name="pair first"/>
            <balise id="b_i2" pos="1105" dir="up" name="pair second"/>
            <balise id="b_c" pos="1800" dir="up" name="home"/>
            <balise id="b_lone" pos="2900" dir="up" absPos="4005" name="lone"/>
          </balises>
        </ocsElements>
      </track>
    </tracks>
    <trackGroups>
      <line id="L1" name="Test line" code="X1">
        <trackRef ref="T1"/>
      </line>
    </trackGroups>
  </infrastructure>
</railml>
"""

MAP24 = """
[lines.L1]
line_code = "9001"
track = "D"
name = "Test line (mapped)"

[initial_pairs]
b_i1 = "05"
"""

RAILML3_HEAD = """<?xml version="1.0" encoding="UTF-8"?>
<railML xmlns="https://www.railml.org/schemas/3.2" version="{version}">
  <common id="co"><positioning>
    <linearPositioningSystems>
      <linearPositioningSystem id="lps1" units="{units}" startMeasure="0" endMeasure="1000"/>
    </linearPositioningSystems>
  </positioning></common>
  <infrastructure id="is">
    <topology><netElements>
      <netElement id="ne1" length="1000">
        <associatedPositioningSystem id="aps1">
          <intrinsicCoordinate id="ic0" intrinsicCoord="0">
            <linearCoordinate positioningSystemRef="lps1" measure="0"/>
          </intrinsicCoordinate>
          <intrinsicCoordinate id="ic1" intrinsicCoord="1">
            <linearCoordinate positioningSystemRef="lps1" measure="1000"/>
          </intrinsicCoordinate>
        </associatedPositioningSystem>
      </netElement>
    </netElements></topology>
    <functionalInfrastructure>
      <lines><line id="ln1">
        <linearLocation id="ll1"><associatedNetElement netElementRef="ne1"/></linearLocation>
      </line></lines>
      <balises>
{balises}
      </balises>
    </functionalInfrastructure>
  </infrastructure>
</railML>
"""


def railml3(balises: str, *, version: str = "3.2", units: str = "m") -> str:
    return RAILML3_HEAD.format(balises=balises, version=version, units=units)


def balise3(ident: str | None, ne: str = "ne1", t: float = 0.5) -> str:
    id_attr = f' id="{ident}"' if ident is not None else ""
    return f'<balise{id_attr}><spotLocation id="sl_{ident}_{t}" netElementRef="{ne}" intrinsicCoord="{t}"/></balise>'
