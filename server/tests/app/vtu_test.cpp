// The hand-written VTK XML output: base64 as RFC 4648 has it, files that are
// XML and hold what they were given.
#include <gtest/gtest.h>

#include "app/vtu.hpp"
#include "app_fixtures.hpp"
#include "mesh/primitives.hpp"

namespace tactile {
namespace {

TEST(Vtu, Base64MatchesTheRfcVectors) {
  // RFC 4648, section 10.
  const std::pair<const char*, const char*> vectors[] = {{"", ""},         {"f", "Zg=="},         {"fo", "Zm8="},
                                                         {"foo", "Zm9v"}, {"foob", "Zm9vYg=="}, {"fooba", "Zm9vYmE="},
                                                         {"foobar", "Zm9vYmFy"}};
  for (const auto& [in, out] : vectors) EXPECT_EQ(encode_base64(in, std::strlen(in)), out) << in;
  std::vector<uint8_t> all(256);
  for (int i = 0; i < 256; ++i) all[size_t(i)] = uint8_t(i);
  EXPECT_EQ(test::decode_base64(encode_base64(all.data(), all.size())), all);
}

TEST(Vtu, FrameRoundTrips) {
  test::TempDir dir;
  TetMesh m = make_box(Vec3(0.0), Vec3(1.0, 2.0, 3.0), {1, 2, 1});
  m.region.assign(m.tets.size(), 0);
  m.region[3] = 2;
  std::vector<double> u(3 * size_t(m.n_nodes())), v(u.size()), density(size_t(m.n_tets()));
  for (size_t i = 0; i < u.size(); ++i) u[i] = 0.001 * double(i), v[i] = -double(i);
  for (size_t e = 0; e < density.size(); ++e) density[e] = 0.5 * double(e);
  write_vtu(dir.file("f.vtu"), VtuFrame{&m, &u, &v, &density});
  const test::XmlElement vtk = test::XmlReader::parse(test::read_file(dir.file("f.vtu")));
  const test::XmlElement& piece = vtk.child("UnstructuredGrid").child("Piece");
  EXPECT_EQ(piece.attr("NumberOfPoints"), std::to_string(m.n_nodes()));
  EXPECT_EQ(piece.attr("NumberOfCells"), std::to_string(m.n_tets()));
  EXPECT_EQ(test::decode_vtk_array<double>(test::find_array(piece.child("PointData"), "velocity")), v);
  EXPECT_EQ(test::decode_vtk_array<double>(test::find_array(piece.child("CellData"), "strain_energy_density")), density);
  const auto material = test::decode_vtk_array<int32_t>(test::find_array(piece.child("CellData"), "material"));
  EXPECT_EQ(material, m.region);

  write_pvd(dir.file("s.pvd"), {{0.0, "a.vtu"}, {0.25, "b.vtu"}});
  const test::XmlElement pvd = test::XmlReader::parse(test::read_file(dir.file("s.pvd")));
  ASSERT_EQ(pvd.child("Collection").children.size(), 2u);
  EXPECT_EQ(pvd.child("Collection").children[1].attr("file"), "b.vtu");
  EXPECT_EQ(pvd.child("Collection").children[1].attr("timestep"), "0.25");
}

TEST(Vtu, TheTestReaderRefusesMalformedXml) {
  for (const char* bad : {"<a>", "<a></b>", "<a x=1/>", "<a x='1' x='2'/>", "<a>1 < 2</a>", "<a/><b/>", "<a>&</a>"})
    EXPECT_THROW(test::XmlReader::parse(bad), std::runtime_error) << bad;
  EXPECT_EQ(test::XmlReader::parse("<?xml version=\"1.0\"?>\n<a k=\"v\"><b/>t&amp;</a>").child("b").name, "b");
}

}  // namespace
}  // namespace tactile
