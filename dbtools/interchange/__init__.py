"""Interchange with other systems: railML in and out, GIS formats for QGIS (GeoJSON,
GeoPackage, GeoParquet), findings for CI (SARIF 2.1.0, JUnit XML) and the review page of a
DB change.

Modules, each small and pure where it can be (files are written by the callers through
:mod:`dbtools.atomic` and :mod:`dbtools.database`):

* :mod:`~dbtools.interchange.xmltree` — safe XML parsing (no DTD entities, no network),
  element paths and lines for findings;
* :mod:`~dbtools.interchange.model` — the version-independent picture of a railML file;
* :mod:`~dbtools.interchange.railml2`, :mod:`~dbtools.interchange.railml3` — readers, with
  their topology (:mod:`~dbtools.interchange.topology2`, :mod:`~dbtools.interchange.topology3`)
  and its rows (:mod:`~dbtools.interchange.topology_rows`);
* :mod:`~dbtools.interchange.mapping` — the ``--line-code`` map; balises, curves and geometry
  → our tables (:mod:`~dbtools.interchange.balises`, :mod:`~dbtools.interchange.balise_groups`,
  :mod:`~dbtools.interchange.curves`,
  :mod:`~dbtools.interchange.geometry`);
* :mod:`~dbtools.interchange.importer` — ``db import``;
* :mod:`~dbtools.interchange.railml_out` — ``db export --format railml`` (railML 3.2; the
  network and balise groups: :mod:`~dbtools.interchange.topology_out`; element writing:
  :mod:`~dbtools.interchange.railml_xml`);
* :mod:`~dbtools.interchange.geojson`, :mod:`~dbtools.interchange.gpkg`,
  :mod:`~dbtools.interchange.geoparquet`, :mod:`~dbtools.interchange.wkb` — GIS exports;
* :mod:`~dbtools.interchange.ci` — SARIF and JUnit;
* :mod:`~dbtools.interchange.review` and :mod:`~dbtools.interchange.mapchanges` — ``db review``.
"""
