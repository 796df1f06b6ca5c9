"""GIS tools: projection, grid geometry, grid building, verification."""
