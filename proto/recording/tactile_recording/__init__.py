"""tactile-recording: the recordings a tactile server writes (proto/RECORDING.md), read, exported and compared.

    from tactile_recording import open_recording
    recording = open_recording("recordings/NAME.mcap")

The reader (tactile_recording.reader), the export to CSV and VTU (tactile_recording.export), two recordings
compared (tactile_recording.compare) and the command `tactile-recording` (tactile_recording.cli). It reads
the protocol through tactile-proto (proto/python); the device bridge needs neither this package nor mcap.
"""

from .reader import TOPICS, Recording, RecordingError, open_recording, recover

__all__ = ["TOPICS", "Recording", "RecordingError", "open_recording", "recover"]
