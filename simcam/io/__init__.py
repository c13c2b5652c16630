"""File input/output: DNG read/write, image output, SIDD .MAT files."""
