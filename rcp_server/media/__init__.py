"""Media: camera paths, videos and spherical video metadata."""
