"""Frames and where they come from, one sub-room per modality (points/ today), plus what every
modality shares: batching, path safety and typed JSON records."""
