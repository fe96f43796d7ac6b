// The HDF5 writer (private hdf5/h5.hpp): what it writes is read back through the libhdf5 C API;
// failures name the file and the object.
#include <doctest/doctest.h>

#include <hdf5.h>

#include <zlib.h>

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "bsp/common/errors.hpp"
#include "hdf5/h5.hpp"
#include "testing.hpp"

using namespace bsp;
using bsp::testing::TempDir;

namespace {

// A read-only handle on `name` inside `file`, closed at the end of the scope.
h5::Handle open_dataset(const h5::Handle& file, const char* name) {
  const hid_t id = H5Dopen2(file.id(), name, H5P_DEFAULT);
  REQUIRE(id >= 0);
  return h5::Handle(id, H5Dclose);
}

h5::Handle open_attr(const h5::Handle& obj, const char* name) {
  const hid_t id = H5Aopen(obj.id(), name, H5P_DEFAULT);
  REQUIRE(id >= 0);
  return h5::Handle(id, H5Aclose);
}

std::string read_string_attr(const h5::Handle& obj, const char* name) {
  const h5::Handle a = open_attr(obj, name);
  const h5::Handle type(H5Aget_type(a.id()), H5Tclose);
  REQUIRE(H5Tis_variable_str(type.id()) > 0);
  char* s = nullptr;
  REQUIRE(H5Aread(a.id(), type.id(), &s) >= 0);
  const std::string out(s);
  H5free_memory(s);
  return out;
}

void write_sample(const std::string& path) {
  h5::File f = h5::File::create(path);
  const h5::Group root = f.root();
  const h5::Group train = root.create_group("train");
  const std::vector<hsize_t> shape = {5, 2};
  const h5::Handle ds =
      train.create_dataset("x", h5::Type::F32, shape, 2, h5::Compression{true, 1});
  const float rows_a[6] = {0, 1, 2, 3, 4, 5}, rows_b[4] = {6, 7, 8, 9};
  train.write_rows(ds, "x", h5::Type::F32, shape, 0, 3, rows_a);
  train.write_rows(ds, "x", h5::Type::F32, shape, 3, 2, rows_b);
  train.write_strings("names", {"a", "b\xc3\xa9"});
  root.attr("title", std::string("clips"));
  root.attr("fov", 90.0);
  root.attr("clip_length", std::int64_t{30});
  root.attr("joints", std::vector<std::int64_t>{1, 2, 3});
  f.close();
}

}  // namespace

TEST_CASE("h5: datasets written in row blocks, chunked and compressed, with attributes") {
  TempDir tmp;
  const std::string path = tmp.path("out.h5");
  write_sample(path);
  const h5::Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  REQUIRE(file.id() >= 0);
  const h5::Handle x = open_dataset(file, "/train/x");
  float values[10] = {};
  REQUIRE(H5Dread(x.id(), H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, values) >= 0);
  for (int i = 0; i < 10; ++i) CHECK(values[i] == static_cast<float>(i));
  const h5::Handle dcpl(H5Dget_create_plist(x.id()), H5Pclose);
  hsize_t chunk[2] = {};
  CHECK(H5Pget_chunk(dcpl.id(), 2, chunk) == 2);
  CHECK((chunk[0] == 2 && chunk[1] == 2));
  CHECK(H5Pget_nfilters(dcpl.id()) == 2);  // shuffle + deflate
  const h5::Handle names = open_dataset(file, "/train/names");
  const h5::Handle str_type(H5Dget_type(names.id()), H5Tclose);
  CHECK(H5Tget_cset(str_type.id()) == H5T_CSET_UTF8);
  char* strs[2] = {nullptr, nullptr};
  REQUIRE(H5Dread(names.id(), str_type.id(), H5S_ALL, H5S_ALL, H5P_DEFAULT, strs) >= 0);
  CHECK(std::string(strs[0]) == "a");
  CHECK(std::string(strs[1]) == "b\xc3\xa9");
  H5free_memory(strs[0]), H5free_memory(strs[1]);
  const h5::Handle root(H5Gopen2(file.id(), "/", H5P_DEFAULT), H5Gclose);
  CHECK(read_string_attr(root, "title") == "clips");
  double fov = 0;
  REQUIRE(H5Aread(open_attr(root, "fov").id(), H5T_NATIVE_DOUBLE, &fov) >= 0);
  CHECK(fov == 90.0);
  std::int64_t L = 0, joints[3] = {};
  REQUIRE(H5Aread(open_attr(root, "clip_length").id(), H5T_NATIVE_INT64, &L) >= 0);
  CHECK(L == 30);
  REQUIRE(H5Aread(open_attr(root, "joints").id(), H5T_NATIVE_INT64, joints) >= 0);
  CHECK((joints[0] == 1 && joints[1] == 2 && joints[2] == 3));
}

TEST_CASE("h5: errors are Hdf5Error naming the file and the object") {
  TempDir tmp;
  const std::string missing = tmp.path("no/such/dir/out.h5");
  CHECK_THROWS_WITH_AS(h5::File::create(missing),
                       doctest::Contains(("cannot create HDF5 file " + missing).c_str()),
                       Hdf5Error);
  const std::string path = tmp.path("twice.h5");
  h5::File f = h5::File::create(path);
  const h5::Group g = f.root().create_group("val");
  g.write_strings("names", {"a"});
  CHECK_THROWS_WITH_AS(g.write_strings("names", {"b"}),
                       doctest::Contains(("cannot create dataset " + path + ":/val/names").c_str()),
                       Hdf5Error);
  f.close();
}

TEST_CASE("h5: ChunkPacker shuffles bytes by element and deflates in zlib's format") {
  // Three float32 elements, bytes 0..11: shuffled, byte j of element i goes to 3 j + i.
  std::uint8_t bytes[12];
  for (int k = 0; k < 12; ++k) bytes[k] = static_cast<std::uint8_t>(k);
  std::vector<std::uint8_t> packed;
  h5::ChunkPacker packer(1);
  packer.pack(bytes, sizeof bytes, 4, packed);
  std::uint8_t plain[12] = {};
  uLongf n = sizeof plain;
  REQUIRE(uncompress(plain, &n, packed.data(), packed.size()) == Z_OK);  // zlib stream
  REQUIRE(n == 12);
  const std::uint8_t shuffled[12] = {0, 4, 8, 1, 5, 9, 2, 6, 10, 3, 7, 11};
  CHECK(std::memcmp(plain, shuffled, 12) == 0);
  packer.pack(bytes, sizeof bytes, 1, packed);  // one-byte elements: no shuffle
  n = sizeof plain;
  REQUIRE(uncompress(plain, &n, packed.data(), packed.size()) == Z_OK);
  CHECK(std::memcmp(plain, bytes, 12) == 0);
}

TEST_CASE("h5: chunks packed by ChunkPacker and written as stored read back through the filters") {
  TempDir tmp;
  const std::string path = tmp.path("chunks.h5");
  const std::vector<hsize_t> shape = {5, 3};  // chunks of 2 rows: the last one is an edge
  std::vector<float> values(15);
  for (std::size_t k = 0; k < values.size(); ++k) values[k] = 0.5f * static_cast<float>(k) - 3;
  {
    h5::File f = h5::File::create(path);
    const h5::Group root = f.root();
    const h5::Handle ds = root.create_dataset("x", h5::Type::F32, shape, 2, h5::Compression{true, 1});
    h5::ChunkPacker packer(1);
    std::vector<std::uint8_t> packed;
    for (hsize_t r = 0; r < 5; r += 2) {
      float chunk[6] = {};  // the edge chunk padded with zeros, as libhdf5 stores it
      std::memcpy(chunk, &values[3 * r], sizeof(float) * 3 * std::min<hsize_t>(2, 5 - r));
      packer.pack(chunk, sizeof chunk, sizeof(float), packed);
      root.write_chunk(ds, "x", {r, 0}, packed);
    }
    f.close();
  }
  const h5::Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  REQUIRE(file.id() >= 0);
  const h5::Handle x = open_dataset(file, "/x");
  std::vector<float> back(15, -1);
  REQUIRE(H5Dread(x.id(), H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, back.data()) >= 0);
  CHECK(back == values);
}
