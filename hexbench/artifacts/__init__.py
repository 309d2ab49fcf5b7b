"""File formats, one owner each: hashing and atomic writes, action logs, result records."""
