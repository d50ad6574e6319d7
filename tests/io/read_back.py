"""Reads a DICOM file Shapecast stored with pydicom (a second, independent DICOM reader) and
prints what a PACS viewer would see of it as JSON: tests/io/dicomweb_orthanc.rs compares it with
what was sent. A Secondary Capture: its frames as decoded pixels; a Structured Report: its
template and measurement groups as a tree of concept names and values.
Usage: python3 tests/io/read_back.py FILE"""

import json
import sys

import pydicom

ds = pydicom.dcmread(sys.argv[1])
out = {
    "sop_class": str(ds.SOPClassUID),
    "study": str(ds.StudyInstanceUID),
    "series_description": str(ds.SeriesDescription),
    "modality": str(ds.Modality),
}


def concept(item):
    return str(item.ConceptNameCodeSequence[0].CodeMeaning)


def content_item(item):
    d = {"concept": concept(item), "value_type": str(item.ValueType)}
    if item.ValueType == "NUM":
        mv = item.MeasuredValueSequence[0]
        d["value"] = float(mv.NumericValue)
        d["unit"] = str(mv.MeasurementUnitsCodeSequence[0].CodeValue)
    elif item.ValueType == "TEXT":
        d["text"] = str(item.TextValue)
    elif item.ValueType == "CODE":
        d["code"] = str(item.ConceptCodeSequence[0].CodeMeaning)
    elif item.ValueType == "SCOORD3D":
        d["graphic_type"] = str(item.GraphicType)
        d["points"] = [float(x) for x in item.GraphicData]
        d["frame_of_reference"] = str(item.ReferencedFrameOfReferenceUID)
    if "ContentSequence" in item:
        d["items"] = [content_item(i) for i in item.ContentSequence]
    return d


if ds.Modality == "SR":
    out["template"] = str(ds.ContentTemplateSequence[0].TemplateIdentifier)
    out["title"] = concept(ds)
    measurements = [i for i in ds.ContentSequence if concept(i) == "Imaging Measurements"]
    out["groups"] = [content_item(g) for g in measurements[0].ContentSequence]
    out["evidence_series"] = str(
        ds.CurrentRequestedProcedureEvidenceSequence[0].ReferencedSeriesSequence[0].SeriesInstanceUID
    )
else:
    pixels = ds.pixel_array  # decoded as a viewer decodes it: frames x rows x columns x RGB
    out.update(
        {
            "frames": int(ds.NumberOfFrames),
            "shape": list(pixels.shape),
            "sum": int(pixels.astype("int64").sum()),
            "frame_time_ms": float(ds.FrameTime),
            "referenced_series": str(ds.ReferencedSeriesSequence[0].SeriesInstanceUID),
            "source_images": len(ds.SourceImageSequence),
        }
    )
print(json.dumps(out))
