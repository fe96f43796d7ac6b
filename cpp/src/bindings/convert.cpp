// bsp-convert binding: the whole conversion, GIL released, progress polled from Python.
#include "bsp/conversion/convert.hpp"
#include "common.hpp"
#include "options.hpp"

namespace bsp::py_bind {
namespace {

py::dict report_dict(const ConvertReport& r) {
  py::dict d;
  d["rows"] = r.rows, d["recordings"] = r.recordings;
  py::dict splits;
  for (int s = 0; s < 3; ++s) {
    py::dict x;
    x["clips"] = r.clips[s], x["recordings"] = r.recordings_per_split[s];
    x["not-crossing"] = r.class_counts[s][0], x["crossing"] = r.class_counts[s][1];
    splits[kSplitNames[s]] = x;
  }
  d["splits"] = splits;
  d["skipped"] = r.skipped;
  d["clips_rejected_out_of_image"] = r.clips_rejected_out_of_image;
  d["clips_dropped_by_balance"] = r.clips_dropped_by_balance;
  d["seconds"] = r.seconds;
  d["source_crc32"] = r.source_crc32, d["source_bytes"] = r.source_bytes;
  py::list v;
  for (const VerifyRow& row : r.verify)
    v.append(py::dict(py::arg("recording") = row.recording, py::arg("component_mm") = row.component_mm,
                      py::arg("world_mm") = row.world_mm, py::arg("camera_px") = row.camera_px));
  d["verify"] = v;
  d["verify_failed"] = r.verify_failed;
  py::dict media;
  media["frames"] = py::dict(py::arg("train") = r.media.frames[0], py::arg("val") = r.media.frames[1],
                             py::arg("test") = r.media.frames[2]);
  media["seconds"] = r.media.seconds, media["check_seconds"] = r.media.check_seconds;
  py::list bad;
  for (const BadMedia& b : r.media.bad) bad.append(py::make_tuple(b.path, b.reason));
  media["bad"] = bad;
  media["passes"] = r.media.passes;
  media["fully_occluded"] = py::dict(py::arg("train") = r.media.fully_occluded[0],
                                     py::arg("val") = r.media.fully_occluded[1],
                                     py::arg("test") = r.media.fully_occluded[2]);
  d["media"] = media;
  py::list failures;
  for (const ShardFailure& f : r.shard_failures)
    failures.append(py::dict(py::arg("phase") = f.phase, py::arg("order") = f.order,
                             py::arg("recording") = py::make_tuple(f.recording.id, f.recording.camera_idx,
                                                                   f.recording.pedestrian_idx),
                             py::arg("path") = f.recording.path, py::arg("reason") = f.recording.reason,
                             py::arg("kind") = f.kind));
  d["shard_failures"] = failures;
  return d;
}

py::dict convert_defaults() {
  const ConvertOptions o;
  py::dict d;
  d["clip_length"] = o.clips.length;
  d["val_frac"] = o.clips.val_frac, d["test_frac"] = o.clips.test_frac;
  d["seed"] = o.clips.seed;
  d["fov"] = o.fov;
  d["crop_size"] = o.media.crop_size;
  d["crop_box"] = crop_box_name(o.media.crop_box);
  d["crop_context"] = o.media.crop_context;
  return d;
}

py::dict convert(const std::string& csv, const std::string& out, ConvertProgress* progress,
                 py::kwargs kw) {
  py::dict d(kw);
  ConvertOptions o;
  o.clips = clip_options(d);
  o.fov = take(d, "fov", o.fov);
  o.threads = take(d, "threads", o.threads);
  o.verify = take(d, "verify", o.verify);
  o.verify_tol_mm = take(d, "verify_tol_mm", o.verify_tol_mm);
  o.verify_world_tol_mm = take(d, "verify_world_tol_mm", o.verify_world_tol_mm);
  o.verify_tol_px = take(d, "verify_tol_px", o.verify_tol_px);
  o.compress = take(d, "compress", o.compress);
  o.compression_level = take(d, "compression_level", o.compression_level);
  o.chunk_clips = take(d, "chunk_clips", o.chunk_clips);
  o.source_path = take(d, "source_path", o.source_path);
  o.media.enabled = take(d, "media", o.media.enabled);
  o.media.crop_size = take(d, "crop_size", o.media.crop_size);
  o.media.crop_box = crop_box_policy(take(d, "crop_box", std::string(crop_box_name(o.media.crop_box))));
  o.media.crop_context = take(d, "crop_context", o.media.crop_context);
  o.media.skip_bad_media = take(d, "skip_bad_media", o.media.skip_bad_media);
  // --compress covers the RGB crops too unless a level is given.
  o.media.rgb_level = take(d, "media_rgb_level", o.compress ? o.compression_level : o.media.rgb_level);
  o.media.mask_level = take(d, "media_mask_level", o.media.mask_level);
  o.media.chunk_frames = take(d, "media_chunk_frames", o.media.chunk_frames);
  o.extra_attrs = take(d, "extra_attrs", o.extra_attrs);
  o.shard.count = take(d, "shard_count", o.shard.count);
  o.shard.index = take(d, "shard_index", o.shard.index);
  // (id, camera_idx, pedestrian_idx, path, reason) of recordings to plan without
  using Left = std::tuple<std::string, std::int64_t, std::int64_t, std::string, std::string>;
  for (const Left& x : take(d, "exclude", std::vector<Left>{}))
    o.shard.exclude.push_back({std::get<0>(x), std::get<1>(x), std::get<2>(x), std::get<3>(x), std::get<4>(x)});
  no_leftovers(d);
  ConvertReport r;
  {
    py::gil_scoped_release nogil;
    r = convert_csv(csv, out, o, progress);
  }
  return report_dict(r);
}

py::dict frame_media_py(const CArray<std::uint8_t>& tags, const CArray<float>& uv,
                        const std::string& policy) {
  if (tags.ndim() != 2) throw py::value_error("tags must be (H, W) class tags, got " + shape_str(tags));
  if (leading_count(uv, {26, 2}, "uv", "(26, 2)") != 1)
    throw py::value_error("uv must be one frame's (26, 2) joints, got " + shape_str(uv));
  const FrameMedia m = frame_media(tags.data(), static_cast<int>(tags.shape(1)),
                                   static_cast<int>(tags.shape(0)), uv.data(),
                                   crop_box_policy(policy));
  auto box = empty<float>({4});
  auto bbox = empty<std::int32_t>({4});
  auto vis = empty<std::uint8_t>({26});
  std::copy(m.crop_box.begin(), m.crop_box.end(), box.mutable_data());
  std::copy(m.mask_bbox.begin(), m.mask_bbox.end(), bbox.mutable_data());
  std::copy(m.joint_visible.begin(), m.joint_visible.end(), vis.mutable_data());
  py::dict d;
  d["crop_box"] = box, d["mask_bbox"] = bbox, d["visible_pixels"] = m.visible_pixels;
  d["joint_visible"] = vis;
  return d;
}

py::array crop_resize_py(const CArray<std::uint8_t>& image, const CArray<float>& box, int size,
                         bool nearest) {
  if (image.ndim() != 2 && image.ndim() != 3)
    throw py::value_error("image must be (H, W) or (H, W, C), got " + shape_str(image));
  const int channels = image.ndim() == 3 ? static_cast<int>(image.shape(2)) : 1;
  if (channels < 1 || channels > 4) throw py::value_error("image must have 1 to 4 channels");
  if (box.ndim() != 1 || box.shape(0) != 4) throw py::value_error("box must be [u0, v0, u1, v1]");
  if (size < 1) throw py::value_error("size must be positive");
  std::vector<py::ssize_t> shape = {size, size};
  if (image.ndim() == 3) shape.push_back(channels);
  auto out = empty<std::uint8_t>(shape);
  const std::array<float, 4> b = {box.data()[0], box.data()[1], box.data()[2], box.data()[3]};
  crop_resize(image.data(), 0, 0, static_cast<int>(image.shape(1)), static_cast<int>(image.shape(0)),
              channels, b, size, nearest, out.mutable_data());
  return out;
}

}  // namespace

BSP_BINDING(convert) {
  using Stage = bsp::ConvertStage;
  py::enum_<Stage>(m, "ConvertStage", "What a running conversion is doing (ConvertProgress.stage).")
      .value("read", Stage::read, "reading data.csv (done/total: rows)")
      .value("plan", Stage::plan, "planning clips")
      .value("verify", Stage::verify, "verifying the poses")
      .value("write", Stage::write, "writing the clips (done/total: clips)")
      .value("done", Stage::done, "finished")
      .value("check_media", Stage::check_media, "opening the media files (done/total: files)")
      .value("media", Stage::media, "cropping the media frames (done/total: frames)");
  using Phase = bsp::FailurePhase;
  py::enum_<Phase>(m, "FailurePhase", py::arithmetic(),
                   "When a shard met a media failure; failures sorted by (phase, order) come "
                   "in the order the one-process converter meets them.")
      .value("open", Phase::open, "while opening the files")
      .value("decode", Phase::decode, "while decoding");
  m.def("convert_defaults", &convert_defaults,
        "The C++ core's conversion defaults (clips, split, seed, fov, crop size); "
        "bsp_fast.defaults.CONVERT must agree (tested).");
  py::class_<bsp::ConvertProgress>(m, "ConvertProgress",
                                   "Counters a running conversion updates; poll from Python.")
      .def(py::init<>())
      .def_property_readonly("stage", [](const bsp::ConvertProgress& p) { return p.stage.load(); },
                             "The ConvertStage the conversion is in.")
      .def_property_readonly("done", [](const bsp::ConvertProgress& p) { return p.done.load(); })
      .def_property_readonly("total", [](const bsp::ConvertProgress& p) { return p.total.load(); })
      .def("cancel", [](bsp::ConvertProgress& p) { p.cancel = true; },
           "Asks the running conversion to stop; it joins its threads and raises Error.")
      .def_property_readonly("cancelled", [](const bsp::ConvertProgress& p) { return p.cancel.load(); });
  m.def("convert_csv", &convert, py::arg("csv_path"), py::arg("out_path"),
        py::arg("progress") = nullptr,
        "Converts data.csv into an HDF5 file of train/val/test clips; returns the report.");
  m.def("frame_media", &frame_media_py, py::arg("tags"), py::arg("uv"),
        py::arg("crop_box") = std::string(bsp::crop_box_name(bsp::MediaOptions{}.crop_box)),
        "Pedestrian statistics of one (H, W) segmentation frame with its (26, 2) joints: "
        "crop_box (all NaN: no crop), mask_bbox, visible_pixels, joint_visible (as "
        "bsp-convert stores them); crop_box policy mask, mask+joints or joints.");
  m.def("context_box", [](const CArray<float>& box, double context) {
          if (box.ndim() != 1 || box.shape(0) != 4) throw py::value_error("box must be [u0, v0, u1, v1]");
          const auto c = bsp::context_box({box.data()[0], box.data()[1], box.data()[2], box.data()[3]}, context);
          auto out = empty<float>({4});
          std::copy(c.begin(), c.end(), out.mutable_data());
          return out;
        }, py::arg("box"), py::arg("context"),
        "The context box bsp-convert stores (frames/context_box) for a crop box and factor.");
  m.def("crop_resize", &crop_resize_py, py::arg("image"), py::arg("box"), py::arg("size"),
        py::arg("nearest") = false,
        "Cuts the integer square box [u0, v0, u1, v1] out of an (H, W[, C]) uint8 image with "
        "zero padding and resizes it to size x size (INTER_AREA, or INTER_NEAREST for tags).");
}

}  // namespace bsp::py_bind
