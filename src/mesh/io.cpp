#include "mesh/io.hpp"

#include <fmt/format.h>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/error.hpp"
#include "mesh/validate.hpp"

namespace trbc {
namespace {

struct Token {
    std::string text;
    int line;
};

// Whitespace-separated tokens with their line numbers; '#' starts a comment to end of line.
std::vector<Token> tokenize(std::istream& in) {
    std::vector<Token> tokens;
    std::string line;
    int lineNo = 0;
    while (std::getline(in, line)) {
        ++lineNo;
        if (auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
        std::istringstream ls(line);
        std::string t;
        while (ls >> t) tokens.push_back({t, lineNo});
    }
    return tokens;
}

class TokenReader {
public:
    TokenReader(std::string path, std::vector<Token> tokens)
        : path_(std::move(path)), tokens_(std::move(tokens)) {}

    bool done() const { return pos_ >= tokens_.size(); }
    std::size_t remaining() const { return tokens_.size() - pos_; }
    // Tokens left on the line of the next token (0 at the end of the file).
    std::size_t leftOnLine() const {
        std::size_t n = 0;
        while (pos_ + n < tokens_.size() && tokens_[pos_ + n].line == tokens_[pos_].line) ++n;
        return n;
    }
    int line() const { return done() ? (tokens_.empty() ? 1 : tokens_.back().line) : tokens_[pos_].line; }

    const Token& next(const std::string& what) {
        if (done())
            throw InputError(fmt::format("{}:{}: file ends early (truncated): expected {}", path_,
                                         line(), what));
        return tokens_[pos_++];
    }

    double number(const std::string& what) {
        const Token& t = next(what);
        char* end = nullptr;
        errno = 0;
        const double v = std::strtod(t.text.c_str(), &end);
        if (end == t.text.c_str() || *end != '\0')
            throw InputError(fmt::format("{}:{}: malformed line: expected {} but found '{}'", path_,
                                         t.line, what, t.text));
        if (!std::isfinite(v))
            throw InputError(fmt::format("{}:{}: {} is '{}' (NaN/Inf coordinates are not allowed)",
                                         path_, t.line, what, t.text));
        return v;
    }

    long integer(const std::string& what) {
        const Token& t = next(what);
        char* end = nullptr;
        errno = 0;
        const long v = std::strtol(t.text.c_str(), &end, 10);
        if (end == t.text.c_str() || *end != '\0' || errno == ERANGE)
            throw InputError(fmt::format("{}:{}: malformed line: expected {} (an integer) but found '{}'",
                                         path_, t.line, what, t.text));
        return v;
    }

private:
    std::string path_;
    std::vector<Token> tokens_;
    std::size_t pos_ = 0;
};

std::ofstream openForWriting(const std::string& path) {
    std::ofstream out(path);
    if (!out) throw InputError(fmt::format("cannot open '{}' for writing", path));
    out.precision(17);
    return out;
}

void finishWriting(std::ofstream& out, const std::string& path) {
    out.flush();
    if (!out) throw InputError(fmt::format("error while writing '{}' (disk full or unwritable?)", path));
}

void checkFields(const Mesh& mesh, const std::vector<VertexField>& fields) {
    for (const auto& f : fields)
        if (f.values.cols() != mesh.numVertices() || (f.values.rows() != 1 && f.values.rows() != 3))
            throw std::invalid_argument(fmt::format(
                "vertex field '{}' must be 1x{} or 3x{}, got {}x{}", f.name, mesh.numVertices(),
                mesh.numVertices(), f.values.rows(), f.values.cols()));
}

}  // namespace

namespace {

std::vector<Token> tokenizeFile(const std::string& path) {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec))
        throw InputError(fmt::format("mesh file '{}' is a directory, not a mesh file", path));
    std::ifstream in(path);
    if (!in) throw InputError(fmt::format("cannot open mesh file '{}' (missing or unreadable)", path));
    return tokenize(in);
}

bool hasExtension(const std::string& path, const std::string& ext) {
    return path.size() >= ext.size() && path.compare(path.size() - ext.size(), ext.size(), ext) == 0;
}

/// Triangles '3 i j k', one per line, as trbc's PLY and VTK writers lay them out.
void readFaceRecords(TokenReader& r, const std::string& path, Mesh& m, MeshSource& source) {
    const long nv = m.X.cols(), nf = m.F.cols();
    source.faceLine.resize(static_cast<std::size_t>(nf));
    for (long f = 0; f < nf; ++f) {
        source.faceLine[f] = r.line();
        if (r.leftOnLine() != 4)
            throw InputError(fmt::format("{}:{}: face {} needs 4 values '3 i j k' on its line", path, source.faceLine[f], f));
        if (r.integer(fmt::format("the vertex count of face {}", f)) != 3)
            throw InputError(fmt::format("{}:{}: face {} is not a triangle", path, source.faceLine[f], f));
        for (int k = 0; k < 3; ++k) {
            const long idx = r.integer(fmt::format("vertex index {} of face {}", k, f));
            if (idx < 0 || idx >= nv)
                throw InputError(fmt::format("{}:{}: face {} has vertex index {} out of range [0, {}]", path, source.faceLine[f], f,
                                             idx, nv - 1));
            m.F(k, f) = static_cast<int>(idx);
        }
    }
}

/// PLY vertex records: x y z and then the other properties, one vertex per line.
void readPlyVertices(TokenReader& r, const std::string& path, Mesh& m, MeshSource& source, long valuesPerVertex) {
    const long nv = m.X.cols();
    source.vertexLine.resize(static_cast<std::size_t>(nv));
    for (long i = 0; i < nv; ++i) {
        source.vertexLine[i] = r.line();
        if (const auto n = r.leftOnLine(); n != static_cast<std::size_t>(valuesPerVertex))
            throw InputError(fmt::format("{}:{}: vertex {} needs {} values on its line but there are {}", path,
                                         source.vertexLine[i], i, valuesPerVertex, n));
        for (long k = 0; k < valuesPerVertex; ++k) {
            const double v = r.number(fmt::format("value {} of vertex {} (of {})", k, i, nv));
            if (k < 3) m.X(k, i) = v;
        }
    }
}

/// A count from a header: at least 4 (closed triangle mesh) and at most the tokens left, which
/// bounds the allocation.
long headerCount(TokenReader& r, const std::string& path, const std::string& what) {
    const int line = r.line();
    const long n = r.integer(what);
    if (n < 4 || static_cast<std::size_t>(n) > r.remaining())
        throw InputError(fmt::format("{}:{}: {} = {} is impossible here (at least 4, at most the {} values that follow)", path, line,
                                     what, n, r.remaining()));
    return n;
}

/// ASCII PLY with x y z first among the vertex properties (others skipped) and triangle faces.
Mesh parsePly(const std::string& path, MeshSource& source) {
    TokenReader r(path, tokenizeFile(path));
    if (r.done() || r.next("the header 'ply'").text != "ply") throw InputError(fmt::format("{}:1: not a PLY file (no 'ply' header)", path));
    long nv = -1, nf = -1, props = 0;
    std::string element;
    while (true) {
        const int line = r.line();
        const std::string key = r.next("the PLY header ('end_header')").text;
        if (key == "end_header") break;
        if (key == "format") {
            if (r.next("the PLY format").text != "ascii")
                throw InputError(fmt::format("{}:{}: only ASCII PLY is supported", path, line));
            r.next("the PLY version");
        } else if (key == "element") {
            element = r.next("the element name").text;
            if (element == "vertex")
                nv = headerCount(r, path, "the vertex count");
            else if (element == "face")
                nf = headerCount(r, path, "the face count");
            else
                throw InputError(fmt::format("{}:{}: unsupported PLY element '{}'", path, line, element));
        } else if (key == "property") {
            while (r.leftOnLine() > 0 && r.line() == line) r.next("a property");
            if (element == "vertex") ++props;
        } else if (key == "comment" || key == "obj_info") {
            while (!r.done() && r.line() == line) r.next("a comment");
        } else {
            throw InputError(fmt::format("{}:{}: unexpected '{}' in the PLY header", path, line, key));
        }
    }
    if (nv < 0 || nf < 0) throw InputError(fmt::format("{}: the PLY header lacks the vertex or the face element", path));
    if (props < 3) throw InputError(fmt::format("{}: the PLY vertices need the properties x y z", path));
    Mesh m;
    m.X.resize(3, nv);
    m.F.resize(3, nf);
    source.path = path;
    readPlyVertices(r, path, m, source, props);
    readFaceRecords(r, path, m, source);
    return m;
}

/// Legacy ASCII VTK POLYDATA: POINTS then POLYGONS of triangles; POINT_DATA after them is ignored.
Mesh parseVtk(const std::string& path, MeshSource& source) {
    TokenReader r(path, tokenizeFile(path));
    while (!r.done() && r.next("POINTS").text != "POINTS") {
    }
    if (r.done()) throw InputError(fmt::format("{}: no POINTS section (not a legacy VTK POLYDATA file)", path));
    const long nv = headerCount(r, path, "the point count");
    r.next("the point type");
    Mesh m;
    m.X.resize(3, nv);
    source.path = path;
    source.vertexLine.resize(static_cast<std::size_t>(nv));
    for (long i = 0; i < nv; ++i) {
        source.vertexLine[i] = r.line();
        for (int k = 0; k < 3; ++k) m.X(k, i) = r.number(fmt::format("coordinate {} of point {} (of {})", "xyz"[k], i, nv));
    }
    const int line = r.line();
    if (r.next("POLYGONS").text != "POLYGONS") throw InputError(fmt::format("{}:{}: expected POLYGONS after the points", path, line));
    const long nf = headerCount(r, path, "the polygon count");
    if (r.integer("the POLYGONS size") != 4 * nf)
        throw InputError(fmt::format("{}:{}: only triangles are supported (POLYGONS size must be 4 x {})", path, line, nf));
    m.F.resize(3, nf);
    readFaceRecords(r, path, m, source);
    return m;
}

}  // namespace

Mesh parseOff(const std::string& path, MeshSource* source) {
    TokenReader r(path, tokenizeFile(path));
    if (r.done()) throw InputError(fmt::format("{}:1: empty file, expected an OFF mesh", path));
    {
        const int line = r.line();
        const Token& head = r.next("the header 'OFF'");
        if (head.text != "OFF")
            throw InputError(fmt::format("{}:{}: expected the header 'OFF' but found '{}'", path, line,
                                         head.text));
    }
    // Each record (the counts, a vertex, a face) fills exactly one line, so that a missing or
    // extra value is reported on its own line instead of shifting every later record.
    const int countLine = r.line();
    if (const auto n = r.leftOnLine(); n != 0 && n != 3)
        throw InputError(fmt::format("{}:{}: the header needs the vertex, face and edge counts "
                                     "'nv nf ne' on one line but this line has {} values",
                                     path, countLine, n));
    const long nv = r.integer("the vertex count");
    const long nf = r.integer("the face count");
    r.integer("the edge count");
    if (nv < 4 || nf < 4)
        throw InputError(fmt::format("{}:{}: a closed triangle mesh needs at least 4 vertices and 4 "
                                     "faces, header says {} vertices and {} faces",
                                     path, countLine, nv, nf));
    // Every record has at least one value: this also bounds the allocations below.
    if (static_cast<std::size_t>(nv) > r.remaining() || static_cast<std::size_t>(nf) > r.remaining())
        throw InputError(fmt::format("{}:{}: header says {} vertices and {} faces but only {} values "
                                     "follow (wrong counts, or truncated file)",
                                     path, countLine, nv, nf, r.remaining()));
    Mesh m;
    m.X.resize(3, nv);
    m.F.resize(3, nf);
    std::vector<int> vLine(static_cast<std::size_t>(nv)), fLine(static_cast<std::size_t>(nf));
    for (long i = 0; i < nv; ++i) {
        vLine[i] = r.line();
        if (const auto n = r.leftOnLine(); n != 0 && n != 3)
            throw InputError(fmt::format("{}:{}: vertex {} needs 3 values 'x y z' on its line but "
                                         "there are {} (missing or extra values)",
                                         path, vLine[i], i, n));
        for (int k = 0; k < 3; ++k)
            m.X(k, i) = r.number(fmt::format("coordinate {} of vertex {} (of {})", "xyz"[k], i, nv));
    }
    for (long f = 0; f < nf; ++f) {
        fLine[f] = r.line();
        const auto values = r.leftOnLine();
        const long n = r.integer(fmt::format("the vertex count of face {} (of {})", f, nf));
        if (n != 3)
            throw InputError(fmt::format("{}:{}: face {} has {} vertices; only triangles (3) are supported",
                                         path, fLine[f], f, n));
        if (values != 4)
            throw InputError(fmt::format("{}:{}: face {} needs 4 values '3 i j k' on its line but there "
                                         "are {} (missing or extra values)",
                                         path, fLine[f], f, values));
        for (int k = 0; k < 3; ++k) {
            const long idx = r.integer(fmt::format("vertex index {} of face {}", k, f));
            if (idx < 0 || idx >= nv)
                throw InputError(fmt::format("{}:{}: face {} has vertex index {} out of range [0, {}]",
                                             path, fLine[f], f, idx, nv - 1));
            m.F(k, f) = static_cast<int>(idx);
        }
    }
    if (!r.done())
        throw InputError(fmt::format("{}:{}: unexpected data after the {} faces announced in the header "
                                     "(wrong counts on line {}?)",
                                     path, r.line(), nf, countLine));
    if (source) *source = MeshSource{path, std::move(vLine), std::move(fLine)};
    return m;
}

Mesh readOff(const std::string& path) {
    MeshSource source;
    Mesh m = parseOff(path, &source);
    validateClosedManifold(m, &source);
    return m;
}

Mesh readMesh(const std::string& path) {
    if (!hasExtension(path, ".ply") && !hasExtension(path, ".vtk")) return readOff(path);
    MeshSource source;
    Mesh m = hasExtension(path, ".ply") ? parsePly(path, source) : parseVtk(path, source);
    validateClosedManifold(m, &source);
    return m;
}

void writeOff(const std::string& path, const Mesh& mesh) {
    auto out = openForWriting(path);
    out << "OFF\n" << mesh.numVertices() << ' ' << mesh.numFaces() << " 0\n";
    for (Eigen::Index i = 0; i < mesh.numVertices(); ++i)
        out << mesh.X(0, i) << ' ' << mesh.X(1, i) << ' ' << mesh.X(2, i) << '\n';
    for (Eigen::Index f = 0; f < mesh.numFaces(); ++f)
        out << "3 " << mesh.F(0, f) << ' ' << mesh.F(1, f) << ' ' << mesh.F(2, f) << '\n';
    finishWriting(out, path);
}

void writePly(const std::string& path, const Mesh& mesh, const std::vector<VertexField>& fields) {
    checkFields(mesh, fields);
    auto out = openForWriting(path);
    out << "ply\nformat ascii 1.0\ncomment written by trbc\nelement vertex " << mesh.numVertices()
        << "\nproperty double x\nproperty double y\nproperty double z\n";
    for (const auto& f : fields) {
        if (f.values.rows() == 1)
            out << "property double " << f.name << '\n';
        else
            for (char c : {'x', 'y', 'z'}) out << "property double " << f.name << '_' << c << '\n';
    }
    out << "element face " << mesh.numFaces() << "\nproperty list uchar int vertex_indices\nend_header\n";
    for (Eigen::Index i = 0; i < mesh.numVertices(); ++i) {
        out << mesh.X(0, i) << ' ' << mesh.X(1, i) << ' ' << mesh.X(2, i);
        for (const auto& f : fields)
            for (Eigen::Index r = 0; r < f.values.rows(); ++r) out << ' ' << f.values(r, i);
        out << '\n';
    }
    for (Eigen::Index f = 0; f < mesh.numFaces(); ++f)
        out << "3 " << mesh.F(0, f) << ' ' << mesh.F(1, f) << ' ' << mesh.F(2, f) << '\n';
    finishWriting(out, path);
}

void writeVtk(const std::string& path, const Mesh& mesh, const std::vector<VertexField>& fields) {
    checkFields(mesh, fields);
    auto out = openForWriting(path);
    const auto nv = mesh.numVertices(), nf = mesh.numFaces();
    out << "# vtk DataFile Version 3.0\ntrbc membrane mesh\nASCII\nDATASET POLYDATA\nPOINTS " << nv
        << " double\n";
    for (Eigen::Index i = 0; i < nv; ++i) out << mesh.X(0, i) << ' ' << mesh.X(1, i) << ' ' << mesh.X(2, i) << '\n';
    out << "POLYGONS " << nf << ' ' << 4 * nf << '\n';
    for (Eigen::Index f = 0; f < nf; ++f)
        out << "3 " << mesh.F(0, f) << ' ' << mesh.F(1, f) << ' ' << mesh.F(2, f) << '\n';
    if (!fields.empty()) out << "POINT_DATA " << nv << '\n';
    for (const auto& f : fields) {
        if (f.values.rows() == 1)
            out << "SCALARS " << f.name << " double 1\nLOOKUP_TABLE default\n";
        else
            out << "VECTORS " << f.name << " double\n";
        for (Eigen::Index i = 0; i < nv; ++i) {
            for (Eigen::Index r = 0; r < f.values.rows(); ++r) out << (r ? " " : "") << f.values(r, i);
            out << '\n';
        }
    }
    finishWriting(out, path);
}

void writeMesh(const std::string& path, const Mesh& mesh, const std::vector<VertexField>& fields) {
    auto endsWith = [&](const char* ext) {
        const std::string e(ext);
        return path.size() >= e.size() && path.compare(path.size() - e.size(), e.size(), e) == 0;
    };
    const auto write = [&](const std::string& p) {
        if (endsWith(".off")) return writeOff(p, mesh);
        if (endsWith(".ply")) return writePly(p, mesh, fields);
        if (endsWith(".vtk")) return writeVtk(p, mesh, fields);
        throw InputError(fmt::format("cannot tell the mesh format of '{}': use the extension .off, .ply or .vtk", path));
    };
    std::error_code ec;
    const auto kind = std::filesystem::status(path, ec).type();
    if (kind != std::filesystem::file_type::not_found && kind != std::filesystem::file_type::regular &&
        kind != std::filesystem::file_type::none)
        return write(path);  // a device or a pipe: in place, checked at the flush
    // Through PATH.tmp and rename(2), so that a failed write leaves no partial mesh behind.
    const std::string tmp = path + ".tmp";
    try {
        write(tmp);
    } catch (const InputError& e) {
        std::filesystem::remove(tmp, ec);
        throw InputError(fmt::format("cannot write '{}': {}", path, e.what()));
    }
    std::filesystem::rename(tmp, path, ec);
    if (ec) {
        const std::string why = ec.message();
        std::filesystem::remove(tmp, ec);
        throw InputError(fmt::format("cannot write '{}': {}", path, why));
    }
}

}  // namespace trbc
