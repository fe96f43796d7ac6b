// Video and APNG readers/writers. Argument checks that need friendly wording live in
// bsp_fast/media.py; sizes are checked again here so the private module cannot overrun.
#include "bsp/media/apng.hpp"
#include "bsp/media/video.hpp"
#include "common.hpp"

#include <optional>

namespace bsp::py_bind {
namespace {

// Number of frames in `a`, which must be (H, W, *tail) or (K, H, W, *tail).
std::size_t frame_count(const py::array& a, py::ssize_t h, py::ssize_t w,
                        std::vector<py::ssize_t> tail, const char* expected) {
  tail.insert(tail.begin(), {h, w});
  const std::size_t k = leading_count(a, tail, "frames", expected);
  if (a.ndim() > static_cast<py::ssize_t>(tail.size()) + 1)
    throw py::value_error(std::string("frames: expected shape ") + expected + ", got " +
                          shape_str(a));
  return k;
}

void video_write(VideoWriter& w, const CArray<std::uint8_t>& frames) {
  const std::size_t k = frame_count(frames, w.height(), w.width(), {3}, "(H, W, 3) or (K, H, W, 3)");
  const std::size_t step = static_cast<std::size_t>(w.width()) * w.height() * 3;
  py::gil_scoped_release nogil;
  for (std::size_t i = 0; i < k; ++i) w.write(frames.data() + i * step);
}

void apng_write(ApngWriter& w, const CArray<std::uint8_t>& frames) {
  const std::size_t k = frame_count(frames, w.height(), w.width(), {}, "(H, W) or (K, H, W)");
  const std::size_t step = static_cast<std::size_t>(w.width()) * w.height();
  py::gil_scoped_release nogil;
  for (std::size_t i = 0; i < k; ++i) w.write(frames.data() + i * step);
}

std::unique_ptr<ApngWriter> make_apng_writer(std::string path, int width, int height,
                                             const CArray<std::uint8_t>& palette, double fps,
                                             bool drop_duplicates, int level) {
  if (palette.ndim() != 2 || palette.shape(0) != 256 || palette.shape(1) != 3)
    throw py::value_error("palette: expected shape (256, 3), got " + shape_str(palette));
  std::vector<std::uint8_t> p(palette.data(), palette.data() + palette.size());
  return std::make_unique<ApngWriter>(std::move(path), width, height, p, fps, drop_duplicates,
                                      level);
}

std::vector<std::int64_t> index_list(const CArray<std::int64_t>& indices) {
  if (indices.ndim() > 1)
    throw py::value_error("indices: expected a 1-D array, got shape " + shape_str(indices));
  return std::vector<std::int64_t>(indices.data(), indices.data() + indices.size());
}

CArray<std::uint8_t> video_read(VideoReader& r, const CArray<std::int64_t>& indices,
                                std::optional<std::array<int, 4>> crop) {
  Crop c;
  if (crop) c = Crop{(*crop)[0], (*crop)[1], (*crop)[2], (*crop)[3]};
  const std::vector<std::int64_t> idx = index_list(indices);
  const py::ssize_t w = c.width ? c.width : r.width() - c.x;
  const py::ssize_t h = c.height ? c.height : r.height() - c.y;
  auto out = empty<std::uint8_t>({static_cast<py::ssize_t>(idx.size()), std::max<py::ssize_t>(h, 0),
                                  std::max<py::ssize_t>(w, 0), 3});
  py::gil_scoped_release nogil;
  r.read(idx, out.mutable_data(), c);
  return out;
}

CArray<std::uint8_t> apng_read(ApngReader& r, const CArray<std::int64_t>& indices) {
  const std::vector<std::int64_t> idx = index_list(indices);
  std::vector<py::ssize_t> shape = {static_cast<py::ssize_t>(idx.size()), r.height(), r.width()};
  if (!r.indexed() && r.channels() > 1) shape.push_back(r.channels());
  auto out = empty<std::uint8_t>(shape);
  py::gil_scoped_release nogil;
  r.read(idx, out.mutable_data());
  return out;
}

py::object apng_palette(const ApngReader& r) {
  const std::vector<std::uint8_t> p = r.palette();
  if (p.empty()) return py::none();
  auto out = empty<std::uint8_t>({static_cast<py::ssize_t>(p.size() / 3), 3});
  std::copy(p.begin(), p.end(), out.mutable_data());
  return std::move(out);
}

// What the two writers bind alike: close (GIL released), frames_written and path.
template <class Writer>
void writer_tail(py::class_<Writer> c, const char* close_doc, const char* written_doc) {
  c.def("close", &Writer::close, py::call_guard<py::gil_scoped_release>(), close_doc)
      .def_property_readonly("frames_written", &Writer::frames_written, written_doc)
      .def_property_readonly("path", &Writer::path, "Final path of the file.");
}

void bind_writers(py::module_& m) {
  auto video = py::class_<VideoWriter>(m, "VideoWriter", "H.264/MP4 writer (RGB frames in).")
      .def(py::init<std::string, int, int, double, std::int64_t, std::string, int>(),
           py::arg("path"), py::arg("width"), py::arg("height"), py::arg("fps") = 30.0,
           py::arg("bitrate") = 1'000'000, py::arg("preset") = "veryfast", py::arg("threads") = 1,
           "Opens <path>.tmp-*; close() renames it to path.")
      .def("write", &video_write, py::arg("frames"),
           "Encodes (H, W, 3) or (K, H, W, 3) uint8 RGB frames (GIL released).");
  writer_tail(video, "Flushes the encoder, writes the trailer and renames the file into place.",
              "Frames encoded so far.");

  auto apng =
      py::class_<ApngWriter>(m, "ApngWriter", "Palette-indexed APNG writer (tag frames in).")
      .def(py::init(&make_apng_writer), py::arg("path"), py::arg("width"), py::arg("height"),
           py::arg("palette"), py::arg("fps") = 30.0, py::arg("drop_duplicates") = false,
           py::arg("level") = 6, "Opens <path>.tmp-*; close() renames it to path.")
      .def("write", &apng_write, py::arg("frames"),
           "Appends (H, W) or (K, H, W) uint8 palette-index frames (GIL released).")
      .def_property_readonly("frames_stored", &ApngWriter::frames_stored,
                             "APNG frames after dropping duplicates.");
  writer_tail(apng, "Stores the last frame, patches acTL and renames the file into place.",
              "Frames passed to write().");
}

void bind_readers(py::module_& m) {
  py::class_<bsp::VideoReader>(m, "VideoReader", "Threaded video decoder (RGB frames out).")
      .def(py::init<std::string, int>(), py::arg("path"), py::arg("threads") = 0,
           py::call_guard<py::gil_scoped_release>(),
           "Opens the file and counts its shown frames (a packet scan, no decoding).")
      .def_property_readonly("frame_count", &bsp::VideoReader::frame_count, "Exact frame count.")
      .def_property_readonly("fps", &bsp::VideoReader::fps, "Average frame rate.")
      .def_property_readonly("width", &bsp::VideoReader::width, "Picture width.")
      .def_property_readonly("height", &bsp::VideoReader::height, "Picture height.")
      .def_property_readonly("codec", &bsp::VideoReader::codec, "Decoder name.")
      .def("read", &video_read, py::arg("indices"), py::arg("crop") = py::none(),
           "Frames `indices` as (K, H, W, 3) uint8 RGB; crop = (x, y, width, height) is "
           "applied before the colour conversion (GIL released).");

  py::class_<bsp::ApngReader>(m, "ApngReader", "APNG/PNG decoder (indices for palette files).")
      .def(py::init<std::string>(), py::arg("path"), py::call_guard<py::gil_scoped_release>(),
           "Reads the file and walks its chunks (CRCs, sequence numbers, frame table).")
      .def_property_readonly("frame_count", &bsp::ApngReader::frame_count, "Frames (acTL).")
      .def_property_readonly("width", &bsp::ApngReader::width, "Canvas width.")
      .def_property_readonly("height", &bsp::ApngReader::height, "Canvas height.")
      .def_property_readonly("channels", &bsp::ApngReader::channels, "Bytes per output pixel.")
      .def_property_readonly("colour_type", &bsp::ApngReader::colour_type, "PNG colour type.")
      .def_property_readonly("indexed", &bsp::ApngReader::indexed, "True for palette files.")
      .def_property_readonly("palette", &apng_palette, "(N, 3) uint8 PLTE, or None.")
      .def_property_readonly("delays", &bsp::ApngReader::delays, "Seconds each frame shows.")
      .def_property_readonly("dispose_ops", &bsp::ApngReader::dispose_ops, "fcTL dispose_op.")
      .def_property_readonly("blend_ops", &bsp::ApngReader::blend_ops, "fcTL blend_op.")
      .def("read", &apng_read, py::arg("indices"),
           "Composited frames `indices`: (K, H, W) for indexed/grey, else (K, H, W, C) (GIL "
           "released).")
      .def("video_to_apng_frames", &bsp::ApngReader::video_to_apng_frames,
           py::arg("n_video_frames"), py::arg("fps"),
           "APNG frame shown at each video frame's time k / fps (-1 after the animation).");
}

}  // namespace

BSP_BINDING(media) {
  bind_writers(m);
  bind_readers(m);
  std::vector<std::string> names(bsp::kTagNames.begin(), bsp::kTagNames.end());
  std::vector<std::array<std::uint8_t, 3>> colors(bsp::kCityscapesColors.begin(),
                                                  bsp::kCityscapesColors.end());
  m.attr("TAG_NAMES") = py::cast(names);
  m.attr("CITYSCAPES_COLORS") = py::cast(colors);
}

}  // namespace bsp::py_bind
