// Video and APNG readers/writers. Argument checks that need friendly wording live in
// bsp_fast/media.py; sizes are checked again here so the private module cannot overrun.
#include "bsp/apng.hpp"
#include "bsp/video.hpp"
#include "common.hpp"

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

}  // namespace
}  // namespace bsp::py_bind

BSP_BINDING(media) {
  using namespace bsp::py_bind;
  namespace py = pybind11;
  using bsp::ApngWriter;
  using bsp::VideoWriter;

  py::class_<VideoWriter>(m, "VideoWriter", "H.264/MP4 writer (RGB frames in).")
      .def(py::init<std::string, int, int, double, std::int64_t, std::string, int>(),
           py::arg("path"), py::arg("width"), py::arg("height"), py::arg("fps") = 30.0,
           py::arg("bitrate") = 1'000'000, py::arg("preset") = "veryfast", py::arg("threads") = 1,
           "Opens <path>.tmp-*; close() renames it to path.")
      .def("write", &video_write, py::arg("frames"),
           "Encodes (H, W, 3) or (K, H, W, 3) uint8 RGB frames (GIL released).")
      .def("close", &VideoWriter::close, py::call_guard<py::gil_scoped_release>(),
           "Flushes the encoder, writes the trailer and renames the file into place.")
      .def_property_readonly("frames_written", &VideoWriter::frames_written,
                             "Frames encoded so far.")
      .def_property_readonly("path", &VideoWriter::path, "Final path of the file.");

  py::class_<ApngWriter>(m, "ApngWriter", "Palette-indexed APNG writer (tag frames in).")
      .def(py::init(&make_apng_writer), py::arg("path"), py::arg("width"), py::arg("height"),
           py::arg("palette"), py::arg("fps") = 30.0, py::arg("drop_duplicates") = false,
           py::arg("level") = 6, "Opens <path>.tmp-*; close() renames it to path.")
      .def("write", &apng_write, py::arg("frames"),
           "Appends (H, W) or (K, H, W) uint8 palette-index frames (GIL released).")
      .def("close", &ApngWriter::close, py::call_guard<py::gil_scoped_release>(),
           "Stores the last frame, patches acTL and renames the file into place.")
      .def_property_readonly("frames_written", &ApngWriter::frames_written,
                             "Frames passed to write().")
      .def_property_readonly("frames_stored", &ApngWriter::frames_stored,
                             "APNG frames after dropping duplicates.")
      .def_property_readonly("path", &ApngWriter::path, "Final path of the file.");

  std::vector<std::string> names(bsp::kTagNames.begin(), bsp::kTagNames.end());
  std::vector<std::array<std::uint8_t, 3>> colors(bsp::kCityscapesColors.begin(),
                                                  bsp::kCityscapesColors.end());
  m.attr("TAG_NAMES") = py::cast(names);
  m.attr("CITYSCAPES_COLORS") = py::cast(colors);
}
