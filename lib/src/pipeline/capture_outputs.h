#pragma once
// Private to the pipeline: what `tprf render` writes for a scene's capture block (capture.hdf5,
// capture.npy, and the sensor's measurements of the capture when the scene has no camera).

#include "arrays.h"
#include "tprf/io/json_records.h"
#include "tprf/pipeline/render.h"

namespace tprf {

struct Scene;
struct PatchSet;
struct LinkSet;
class Visibility;

/// The render flags that need a camera (frames, streaks, video, patch profiles, a plot pixel) are bad
/// flags for a scene that has only a capture.
void check_capture_flags(const RenderOptions& options);

/// What a capture is computed over: the built patches, their visibility and the links, which may be
/// null when the capture needs none (capture_needs_links).
struct CaptureInputs {
    const PatchSet& patches;
    const Visibility& visibility;
    const LinkSet* links;
};

/// Computes the scene's capture (pipeline/capture.h) and puts its outputs into `arrays` (files: also
/// capture.hdf5, and the sensor's files); adds its seconds to report.seconds.
CaptureRecord render_capture(const Scene& scene, const RenderOptions& options, const CaptureInputs& in, Arrays& arrays,
                             RenderReport& report);

/// On a rank other than 0 of a split render (pipeline/ranks.h): computes this rank's share of the
/// capture and sends it to rank 0, which calls render_capture meanwhile. Writes nothing.
void share_capture(const Scene& scene, const RenderOptions& options, const CaptureInputs& in);

}  // namespace tprf
