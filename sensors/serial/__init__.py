"""Serial boards: framings (codec), capture to a crash-safe raw log, and a virtual board that plays a source."""
