#include "mesh/io.hpp"

#include <fmt/format.h>

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
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
    if (!out) {
        // A path that cannot exist or be written by this user is the caller's input (exit 2); the
        // rest (disk full, file system errors) is the system's (exit 5).
        const int err = errno;
        const std::string what = fmt::format("cannot open '{}' for writing: {}", path, std::strerror(err));
        if (err == ENOENT || err == ENOTDIR || err == EACCES || err == EISDIR || err == EROFS) throw InputError(what);
        throw IoError(what);
    }
    out.precision(17);
    return out;
}

void finishWriting(std::ofstream& out, const std::string& path) {
    errno = 0;
    out.flush();
    if (!out) throw IoError(fmt::format("error while writing '{}': {}", path, errno != 0 ? std::strerror(errno) : "write failed"));
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

namespace {

// Whitespace-separated tokens of a text file after its first `skipLines` lines, with line numbers.
struct TokenStream {
    std::string path;
    std::vector<Token> tokens;
    std::size_t pos = 0;
    bool done() const { return pos >= tokens.size(); }
    const Token& next(const char* what) {
        if (done()) throw InputError(fmt::format("{}: unexpected end of file (expected {})", path, what));
        return tokens[pos++];
    }
    double number(const char* what) {
        const Token& t = next(what);
        char* end = nullptr;
        errno = 0;
        const double v = std::strtod(t.text.c_str(), &end);
        if (end == t.text.c_str() || *end != '\0' || !std::isfinite(v))
            throw InputError(fmt::format("{}:{}: expected {} (a number), got '{}'", path, t.line, what, t.text));
        return v;
    }
    long index(const char* what) {
        const double v = number(what);  // an InputError at the end of the file
        const Token& t = tokens[pos - 1];
        if (v != std::floor(v) || v < 0 || v > 2e9)
            throw InputError(fmt::format("{}:{}: expected {} (a non-negative integer), got '{}'", path, t.line, what, t.text));
        return static_cast<long>(v);
    }
    /// A count of items of `perItem` tokens each that must all follow: bounded by what is left, so
    /// that a corrupted count is an error instead of a huge allocation.
    long count(const char* what, long perItem) {
        const long n = index(what);
        if (static_cast<double>(n) * static_cast<double>(perItem) > static_cast<double>(tokens.size() - pos))
            throw InputError(fmt::format("{}:{}: {} = {} is more than the file holds", path, tokens[pos - 1].line, what, n));
        return n;
    }
};

TokenStream tokenize(const std::string& path, std::istream& in, int firstLine) {
    TokenStream ts;
    ts.path = path;
    std::string line;
    int lineNo = firstLine;
    while (std::getline(in, line)) {
        ++lineNo;
        std::istringstream ls(line);
        std::string w;
        while (ls >> w) ts.tokens.push_back({w, lineNo});
    }
    return ts;
}

void checkFaceIndex(const TokenStream& ts, long v, Eigen::Index nv) {
    if (v >= nv) throw InputError(fmt::format("{}: face vertex index {} out of range (the mesh has {} vertices)", ts.path, v, nv));
}

Mesh readPly(const std::string& path) {
    std::ifstream in(path);
    if (!in) throw InputError(fmt::format("cannot open '{}'", path));
    std::string line;
    int lineNo = 0;
    auto header = [&]() {
        if (!std::getline(in, line)) throw InputError(fmt::format("{}: unexpected end of the PLY header", path));
        ++lineNo;
        std::istringstream ls(line);
        std::vector<std::string> w;
        std::string t;
        while (ls >> t) w.push_back(t);
        return w;
    };
    if (header() != std::vector<std::string>{"ply"}) throw InputError(fmt::format("{}:1: not a PLY file (first line must be 'ply')", path));
    long nv = -1, nf = -1;
    int vertexProperties = 0, xyz[3] = {-1, -1, -1}, faceScalarsBefore = 0, faceScalarsAfter = 0;
    bool faceList = false;
    std::string element;
    for (;;) {
        const std::vector<std::string> w = header();
        if (w.empty() || w[0] == "comment" || w[0] == "obj_info") continue;
        if (w[0] == "end_header") break;
        if (w[0] == "format") {
            if (w.size() < 2 || w[1] != "ascii")
                throw InputError(fmt::format("{}:{}: only ASCII PLY is read (format '{}')", path, lineNo, w.size() > 1 ? w[1] : ""));
        } else if (w[0] == "element" && w.size() == 3) {
            element = w[1];
            const long n = std::atol(w[2].c_str());
            if (element == "vertex") nv = n;
            else if (element == "face") nf = n;
            else if (n > 0) throw InputError(fmt::format("{}:{}: unsupported PLY element '{}'", path, lineNo, element));
        } else if (w[0] == "property" && element == "vertex") {
            if (w.size() != 3) throw InputError(fmt::format("{}:{}: unsupported vertex property '{}'", path, lineNo, line));
            for (int c = 0; c < 3; ++c)
                if (w[2] == std::string(1, char('x' + c))) xyz[c] = vertexProperties;
            ++vertexProperties;
        } else if (w[0] == "property" && element == "face") {
            if (w.size() == 5 && w[1] == "list" && (w[4] == "vertex_indices" || w[4] == "vertex_index")) faceList = true;
            else (faceList ? faceScalarsAfter : faceScalarsBefore)++;
        }
    }
    if (nv < 0 || nf < 0 || !faceList || xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0)
        throw InputError(fmt::format("{}: the PLY header needs a vertex element with x, y, z and a face element with vertex_indices", path));
    TokenStream ts = tokenize(path, in, lineNo);
    if (static_cast<double>(nv) * vertexProperties + static_cast<double>(nf) * (4 + faceScalarsBefore + faceScalarsAfter) >
        static_cast<double>(ts.tokens.size()))
        throw InputError(fmt::format("{}: the header announces {} vertices and {} faces, more than the file holds", path, nv, nf));
    Mesh m;
    m.X.resize(3, nv);
    for (long i = 0; i < nv; ++i)
        for (int p = 0; p < vertexProperties; ++p) {
            const double v = ts.number("a vertex property");
            for (int c = 0; c < 3; ++c)
                if (xyz[c] == p) m.X(c, i) = v;
        }
    m.F.resize(3, nf);
    for (long f = 0; f < nf; ++f) {
        for (int k = 0; k < faceScalarsBefore; ++k) ts.number("a face property");
        if (ts.index("the number of face vertices") != 3)
            throw InputError(fmt::format("{}:{}: face {} is not a triangle", path, ts.tokens[ts.pos - 1].line, f));
        for (int c = 0; c < 3; ++c) {
            const long v = ts.index("a vertex index");
            checkFaceIndex(ts, v, nv);
            m.F(c, f) = static_cast<int>(v);
        }
        for (int k = 0; k < faceScalarsAfter; ++k) ts.number("a face property");
    }
    return m;
}

Mesh readVtk(const std::string& path) {
    std::ifstream in(path);
    if (!in) throw InputError(fmt::format("cannot open '{}'", path));
    std::string line;
    int lineNo = 0;
    std::string head[3];
    for (std::string& h : head) {
        if (!std::getline(in, h)) throw InputError(fmt::format("{}: not a legacy VTK file (fewer than 3 lines)", path));
        ++lineNo;
    }
    if (head[0].rfind("# vtk DataFile", 0) != 0) throw InputError(fmt::format("{}:1: not a legacy VTK file", path));
    if (head[2].find("ASCII") == std::string::npos) throw InputError(fmt::format("{}:3: only ASCII VTK is read", path));
    TokenStream ts = tokenize(path, in, lineNo);
    Mesh m;
    bool havePoints = false, haveFaces = false;
    std::vector<long> cellTypes;
    while (!ts.done()) {
        const Token& key = ts.next("a keyword");
        if (key.text == "DATASET") {
            const Token& kind = ts.next("the dataset type");
            if (kind.text != "POLYDATA" && kind.text != "UNSTRUCTURED_GRID")
                throw InputError(fmt::format("{}:{}: dataset {} is not read (POLYDATA or UNSTRUCTURED_GRID)", path, kind.line, kind.text));
        } else if (key.text == "POINTS") {
            const long n = ts.count("the number of points", 3);
            ts.next("the point data type");
            m.X.resize(3, n);
            for (long i = 0; i < n; ++i)
                for (int c = 0; c < 3; ++c) m.X(c, i) = ts.number("a point coordinate");
            havePoints = true;
        } else if (key.text == "POLYGONS" || key.text == "CELLS") {
            const long a = ts.count("the number of cells", 1);
            const long b = ts.count("the size of the cell list", 1);
            std::vector<long> offsets, connectivity;
            if (!ts.done() && ts.tokens[ts.pos].text == "OFFSETS") {  // VTK 5.1: offsets and connectivity arrays
                ts.pos += 2;
                for (long i = 0; i < a; ++i) offsets.push_back(ts.index("a cell offset"));
                if (ts.next("CONNECTIVITY").text != "CONNECTIVITY") throw InputError(fmt::format("{}: CONNECTIVITY expected after OFFSETS", path));
                ts.next("the connectivity data type");
                for (long i = 0; i < b; ++i) connectivity.push_back(ts.index("a vertex index"));
            } else {
                offsets.push_back(0);
                for (long i = 0; i < a; ++i) {
                    const long k = ts.index("the number of cell vertices");
                    for (long j = 0; j < k; ++j) connectivity.push_back(ts.index("a vertex index"));
                    offsets.push_back(static_cast<long>(connectivity.size()));
                }
            }
            const long nf = static_cast<long>(offsets.size()) - 1;
            m.F.resize(3, std::max(0L, nf));
            for (long f = 0; f < nf; ++f) {
                if (offsets[f + 1] - offsets[f] != 3) throw InputError(fmt::format("{}: cell {} is not a triangle", path, f));
                if (offsets[f] < 0 || offsets[f] + 3 > static_cast<long>(connectivity.size()))
                    throw InputError(fmt::format("{}: the offsets of cell {} lie outside the connectivity list", path, f));
                for (int c = 0; c < 3; ++c) m.F(c, f) = static_cast<int>(connectivity[offsets[f] + c]);
            }
            haveFaces = true;
        } else if (key.text == "CELL_TYPES") {
            const long n = ts.count("the number of cell types", 1);
            for (long i = 0; i < n; ++i) cellTypes.push_back(ts.index("a cell type"));
        } else if (key.text == "POINT_DATA" || key.text == "CELL_DATA" || key.text == "METADATA" || key.text == "FIELD") {
            break;  // per-vertex fields are not part of the mesh
        } else {
            throw InputError(fmt::format("{}:{}: unexpected '{}' in a legacy VTK file", path, key.line, key.text));
        }
    }
    if (!havePoints || !haveFaces) throw InputError(fmt::format("{}: the VTK file needs POINTS and POLYGONS (or triangle CELLS)", path));
    for (long t : cellTypes)
        if (t != 5) throw InputError(fmt::format("{}: cell type {} is not a triangle (5)", path, t));
    for (Eigen::Index f = 0; f < m.F.cols(); ++f)
        for (int c = 0; c < 3; ++c) checkFaceIndex(ts, m.F(c, f), m.X.cols());
    return m;
}

bool hasExtension(const std::string& path, const char* ext) {
    const std::string e(ext);
    return path.size() >= e.size() && path.compare(path.size() - e.size(), e.size(), e) == 0;
}

}  // namespace

Mesh readMesh(const std::string& path) {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec))
        throw InputError(fmt::format("mesh file '{}' is a directory, not a mesh file", path));
    // A path without an extension is read as OFF (trbc's own format).
    if (hasExtension(path, ".off") || std::filesystem::path(path).extension().empty()) return readOff(path);
    if (!hasExtension(path, ".ply") && !hasExtension(path, ".vtk"))
        throw InputError(fmt::format("{}: unknown mesh format (the extension must be .off, .ply or .vtk)", path));
    const Mesh m = hasExtension(path, ".ply") ? readPly(path) : readVtk(path);
    MeshSource source;
    source.path = path;
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
    // Through PATH.tmp.<pid>.<n> and rename(2), so that a failed write leaves no partial mesh
    // behind and concurrent writers never share a temporary.
    static std::atomic<unsigned long> temporaries{0};
    const std::string tmp = fmt::format("{}.tmp.{}.{}", path, ::getpid(), temporaries++);
    try {
        write(tmp);
    } catch (const IoError& e) {
        std::filesystem::remove(tmp, ec);
        throw IoError(fmt::format("cannot write '{}': {}", path, e.what()));
    } catch (const InputError& e) {
        std::filesystem::remove(tmp, ec);
        throw InputError(fmt::format("cannot write '{}': {}", path, e.what()));
    }
    std::filesystem::rename(tmp, path, ec);
    if (ec) {
        const std::string why = ec.message();
        std::filesystem::remove(tmp, ec);
        throw IoError(fmt::format("cannot write '{}': {}", path, why));
    }
}

}  // namespace trbc
