"""Reading and writing files at motorid's edge (DAQ formats, channel maps)."""
