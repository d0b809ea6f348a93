// Malformed OFF meshes (tests/data/bad_meshes/): readOff must reject each one with an InputError
// naming the file, the line (where one applies) and the problem, and the CLI must print that
// message as "trbc: error: <message>", exit with status 2 and write no output file.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <sstream>
#include <string>

#include "core/error.hpp"
#include "mesh/io.hpp"
#include "test_support.hpp"

namespace {

namespace fs = std::filesystem;
using trbc::test::CliRun;
using trbc::test::shellQuote;
using trbc::test::slurp;
using trbc::test::TempDir;

CliRun runCli(const std::string& args, const TempDir& tmp) { return trbc::test::runTrbc(args, tmp.path()); }

struct BadMesh {
    const char* file;    ///< in tests/data/bad_meshes (missing.off deliberately does not exist)
    int line;            ///< expected "file:line: " prefix; 0: "file: " (whole-mesh problem); -1: file named anywhere
    const char* phrase;  ///< identifies the problem; must not occur in any other case's message
};

std::ostream& operator<<(std::ostream& os, const BadMesh& c) { return os << c.file; }

const BadMesh kCases[] = {
    {"malformed_coordinate.off", 5, "malformed line: expected coordinate y of vertex 2 (of 6) but found 'abc'"},
    {"truncated.off", 14, "file ends early (truncated): expected the vertex count of face 6 (of 8)"},
    {"extra_face.off", 17, "unexpected data after the 8 faces announced in the header"},
    {"extra_value.off", 4, "vertex 1 needs 3 values 'x y z' on its line but there are 4"},
    {"face_extra_value.off", 15, "face 6 needs 4 values '3 i j k' on its line but there are 5"},
    {"bad_counts.off", 2, "the header needs the vertex, face and edge counts 'nv nf ne' on one line but this line has 2 values"},
    {"huge_counts.off", 2, "header says 6 vertices and 80000000000 faces but only 50 values follow"},
    {"index_out_of_range.off", 12, "face 3 has vertex index 6 out of range [0, 5]"},
    {"negative_index.off", 11, "face 2 has vertex index -1 out of range [0, 5]"},
    {"nan_coordinate.off", 5, "coordinate y of vertex 2 (of 6) is 'nan' (NaN/Inf coordinates are not allowed)"},
    {"inf_coordinate.off", 7, "coordinate z of vertex 4 (of 6) is '-inf' (NaN/Inf coordinates are not allowed)"},
    {"non_triangle.off", 12, "face 4 has 4 vertices; only triangles (3) are supported"},
    {"repeated_vertex.off", 11, "face 2 (1 1 4) is degenerate: it repeats a vertex"},
    {"zero_area.off", 12, "face 3 (3 0 4) is degenerate: its area is 0 (collinear or coincident vertices)"},
    {"duplicate_face.off", 17, "face 8 (4 0 2) duplicates face 0 (line 9)"},
    {"open_boundary.off", 12, "edge (0, 3) belongs to this face only: the surface has an open boundary"},
    {"nonmanifold_edge.off", 10, "non-manifold edge (0, 2) shared by 3 faces"},
    {"flipped_face.off", 14, "inconsistent orientation: this face and face 1 (line 10) traverse edge (1, 2)"},
    {"isolated_vertex.off", 9, "vertex 6 belongs to no face (isolated vertex)"},
    {"torus.off", 0, "the surface has genus 1 (Euler characteristic V - E + F = 12 - 36 + 24 = 0)"},
    {"two_components.off", 0, "the mesh has 2 disconnected pieces"},
    {"inward.off", 0, "faces are oriented inwards"},
    {"empty.off", 1, "empty file, expected an OFF mesh"},
    {"bad_header.off", 1, "expected the header 'OFF' but found 'ply'"},
    {"missing.off", -1, "cannot open mesh file"},
};

const fs::path kDir = fs::path(TRBC_TEST_DATA) / "bad_meshes";

std::string pathOf(const char* file) { return (kDir / file).string(); }


/// The InputError message of readOff(path); fails the test (and returns "") if there is none.
std::string readOffError(const std::string& path) {
    try {
        trbc::readOff(path);
    } catch (const trbc::InputError& e) {
        return e.what();
    } catch (const std::exception& e) {
        ADD_FAILURE() << "readOff(" << path << ") threw a non-InputError: " << e.what();
        return "";
    }
    ADD_FAILURE() << "readOff(" << path << ") accepted the mesh";
    return "";
}


class BadMeshTest : public ::testing::TestWithParam<BadMesh> {};

TEST_P(BadMeshTest, ReadOffThrowsInputError) {
    const BadMesh& c = GetParam();
    const std::string path = pathOf(c.file);
    if (c.line == -1)
        ASSERT_FALSE(fs::exists(path)) << path;
    else
        ASSERT_TRUE(fs::is_regular_file(path)) << path;
    const std::string msg = readOffError(path);
    ASSERT_FALSE(msg.empty());
    if (c.line > 0) {
        const std::string prefix = path + ":" + std::to_string(c.line) + ": ";
        EXPECT_EQ(msg.rfind(prefix, 0), 0u) << "expected the prefix '" << prefix << "' in: " << msg;
    } else if (c.line == 0) {
        EXPECT_EQ(msg.rfind(path + ": ", 0), 0u) << "expected the prefix '" << path << ": ' in: " << msg;
    } else {
        EXPECT_NE(msg.find("'" + path + "'"), std::string::npos) << msg;
    }
    EXPECT_NE(msg.find(c.phrase), std::string::npos) << "expected '" << c.phrase << "' in: " << msg;
    // The phrase identifies this problem only: no other case's phrase may appear in the message.
    for (const BadMesh& other : kCases) {
        if (std::string(other.file) == c.file) continue;
        EXPECT_EQ(msg.find(other.phrase), std::string::npos)
            << other.file << "'s phrase '" << other.phrase << "' also appears in: " << msg;
    }
}

TEST_P(BadMeshTest, CliMeshInfoExits2WithMessage) {
    const BadMesh& c = GetParam();
    const std::string path = pathOf(c.file);
    const std::string msg = readOffError(path);
    ASSERT_FALSE(msg.empty());
    const TempDir tmp;
    const CliRun r = runCli("mesh info " + shellQuote(path), tmp);
    EXPECT_EQ(r.status, 2);
    EXPECT_EQ(r.err, "trbc: error: " + msg + "\n");
    EXPECT_EQ(r.out, "");
}

TEST_P(BadMeshTest, CliForcesExits2WithMessageAndNoOutput) {
    const BadMesh& c = GetParam();
    const std::string path = pathOf(c.file);
    const std::string msg = readOffError(path);
    ASSERT_FALSE(msg.empty());
    const TempDir tmp;
    const fs::path csv = tmp.path() / "forces.csv";
    const CliRun r =
        runCli("forces --mesh " + shellQuote(path) + " --kb 1 --out " + shellQuote(csv.string()), tmp);
    EXPECT_EQ(r.status, 2);
    EXPECT_EQ(r.err, "trbc: error: " + msg + "\n");
    EXPECT_EQ(r.out, "");
    EXPECT_FALSE(fs::exists(csv)) << "an output file was written for a rejected mesh";
}

std::string caseName(const ::testing::TestParamInfo<BadMesh>& info) {
    return fs::path(info.param.file).stem().string();
}

INSTANTIATE_TEST_SUITE_P(BadMeshes, BadMeshTest, ::testing::ValuesIn(kCases), caseName);

// Positive control: the octahedron all the bad meshes are built from is accepted, and the same
// CLI invocations succeed and write their output (so the checks above can fail).
TEST(BadMeshesControl, OctahedronAcceptedByReadOff) {
    const trbc::Mesh m = trbc::readOff(pathOf("good_octahedron.off"));
    EXPECT_EQ(m.numVertices(), 6);
    EXPECT_EQ(m.numFaces(), 8);
}

TEST(BadMeshesControl, OctahedronAcceptedByCliMeshInfo) {
    const TempDir tmp;
    const CliRun r = runCli("mesh info " + shellQuote(pathOf("good_octahedron.off")), tmp);
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(r.err, "");
    EXPECT_NE(r.out.find("\"vertices\": 6"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("\"faces\": 8"), std::string::npos) << r.out;
}

TEST(BadMeshesControl, OctahedronAcceptedByCliForces) {
    const TempDir tmp;
    const fs::path csv = tmp.path() / "forces.csv";
    const CliRun r = runCli(
        "forces --mesh " + shellQuote(pathOf("good_octahedron.off")) + " --kb 1 --out " + shellQuote(csv.string()),
        tmp);
    EXPECT_EQ(r.status, 0) << r.err;
    ASSERT_TRUE(fs::exists(csv));
    std::istringstream rows(slurp(csv));
    std::string line;
    int n = 0;
    ASSERT_TRUE(std::getline(rows, line));
    EXPECT_TRUE(line.starts_with("# trbc ")) << line;  // the provenance line
    ASSERT_TRUE(std::getline(rows, line));
    EXPECT_EQ(line, "fx,fy,fz");
    while (std::getline(rows, line)) ++n;
    EXPECT_EQ(n, 6);
}

// Every file in bad_meshes/ is exercised above and described in its README.md, and vice versa.
TEST(BadMeshesControl, EveryFileIsTestedAndDocumented) {
    std::set<std::string> tested{"good_octahedron.off"};
    for (const BadMesh& c : kCases)
        if (c.line != -1) tested.insert(c.file);
    std::set<std::string> present;
    for (const auto& e : fs::directory_iterator(kDir))
        if (e.path().extension() == ".off") present.insert(e.path().filename().string());
    EXPECT_EQ(present, tested);
    const std::string readme = slurp(kDir / "README.md");
    for (const auto& f : present) {
        EXPECT_NE(readme.find("`" + f + "`"), std::string::npos) << f << " is not described in README.md";
    }
}

}  // namespace
