// The clip planner on its own (docs/dataset-format.md,
// "7. From rows to clips and splits"), for tests and in-memory re-splitting.
#include "bsp/clips/clips.hpp"
#include "common.hpp"
#include "options.hpp"

namespace bsp::py_bind {
namespace {

py::dict plan_dict(const Plan& plan) {
  py::dict out;
  for (int s = 0; s < 3; ++s) {
    const auto& clips = plan.splits[s];
    const auto n = static_cast<py::ssize_t>(clips.size());
    CArray<std::int64_t> rec(n), first(n), seg(n), idx(n), label(n), tte(n);
    for (py::ssize_t i = 0; i < n; ++i) {
      const Clip& c = clips[static_cast<std::size_t>(i)];
      rec.mutable_at(i) = c.recording, first.mutable_at(i) = c.first;
      seg.mutable_at(i) = c.segment, idx.mutable_at(i) = c.index, label.mutable_at(i) = c.label;
      tte.mutable_at(i) = c.time_to_event;
    }
    py::dict d;
    d["recording"] = rec, d["first"] = first, d["segment"] = seg, d["index"] = idx;
    d["label"] = label, d["time_to_event"] = tte;  // -1: no event (not benchmark mode)
    d["recordings"] = plan.split_recordings[s];
    out[kSplitNames[s]] = d;
  }
  py::list recs;
  for (const Recording& r : plan.recordings) recs.append(py::cast(r.rows));
  out["recording_rows"] = recs;
  py::list skipped;
  for (const auto& s : plan.skipped) skipped.append(py::make_tuple(s.recording, s.reason));
  out["skipped"] = skipped;
  out["clips_rejected_out_of_image"] = plan.clips_rejected_out_of_image;
  out["clips_dropped_by_balance"] = plan.clips_dropped_by_balance;
  return out;
}

py::dict plan(const CArray<std::int32_t>& id, const CArray<std::int64_t>& cam,
              const CArray<std::int64_t>& ped, const CArray<std::int64_t>& frame,
              const CArray<std::uint8_t>& crossing, const CArray<float>& uv,
              const CArray<std::int64_t>& width, const CArray<std::int64_t>& height,
              py::kwargs kw) {
  const std::size_t n = leading_count(uv, {-1, 2}, "pose_camera", "(N, J, 2)");
  for (const py::array* a : std::initializer_list<const py::array*>{&id, &cam, &ped, &frame, &crossing, &width, &height})
    if (a->ndim() != 1 || static_cast<std::size_t>(a->shape(0)) != n)
      throw py::value_error("plan_clips: every key array must be 1-D with " + std::to_string(n) +
                            " rows, got " + shape_str(*a));
  py::dict d(kw);
  const ClipOptions opt = clip_options(d);
  no_leftovers(d);
  RowKeys k{n, id.data(), cam.data(), ped.data(), frame.data(), crossing.data(), uv.data(),
            width.data(), height.data(), static_cast<int>(uv.shape(1))};
  Plan p;
  {
    py::gil_scoped_release nogil;
    p = plan_clips(k, opt);
  }
  return plan_dict(p);
}

}  // namespace

BSP_BINDING(clips) {
  m.def("plan_clips", &plan, py::arg("id_code"), py::arg("camera_idx"), py::arg("pedestrian_idx"),
        py::arg("frame_idx"), py::arg("is_crossing"), py::arg("pose_camera"), py::arg("width"),
        py::arg("height"),
        "Recordings, segments, clips, labels and the seeded split (docs/dataset-format.md, "
        "\"7. From rows to clips and splits\") from row keys.");
}

}  // namespace bsp::py_bind
