"""Reads a DICOM file Shapecast stored with pydicom (a second, independent DICOM reader) and
prints what a PACS viewer would see of it as JSON: tests/io/dicomweb_orthanc.rs compares it with
what was sent. Usage: python3 tests/io/read_back.py FILE"""

import json
import sys

import pydicom

ds = pydicom.dcmread(sys.argv[1])
pixels = ds.pixel_array  # decoded as a viewer decodes it: frames x rows x columns x RGB
print(
    json.dumps(
        {
            "sop_class": str(ds.SOPClassUID),
            "study": str(ds.StudyInstanceUID),
            "series_description": str(ds.SeriesDescription),
            "modality": str(ds.Modality),
            "frames": int(ds.NumberOfFrames),
            "shape": list(pixels.shape),
            "sum": int(pixels.astype("int64").sum()),
            "frame_time_ms": float(ds.FrameTime),
            "referenced_series": str(ds.ReferencedSeriesSequence[0].SeriesInstanceUID),
            "source_images": len(ds.SourceImageSequence),
        }
    )
)
