"""The pyrender TTES stub (seed 002, sections 3.5, 4 and 7): figures from TIPS, scene graphs, terrain, keys,
the window and headless rendering."""
