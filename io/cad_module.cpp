// The CAD module: all of flank's Open CASCADE code, opened by io/cad.cpp through the table of
// io/cad_module.h. Built twice (io/CMakeLists.txt): libflank_cad.so for STEP, and
// libflank_cad_iges.so (FLANK_CAD_IGES) for STEP and IGES, as IGES's translator makes every
// opening a quarter longer; io/cad.cpp opens the second for IGES files only. Every OCCT exception
// becomes io::Error with the file's name; OCCT's own console messages are switched off, so a
// bad file gives one line and nothing else.
#include "io/cad_module.h"

#ifndef FLANK_CAD_IGES
#define FLANK_CAD_IGES 0  // the STEP build
#endif

#include <BRepAdaptor_Surface.hxx>
#include <BRepBndLib.hxx>
#include <BRepBuilderAPI_MakeEdge.hxx>
#include <BRepBuilderAPI_MakeFace.hxx>
#include <BRepBuilderAPI_MakeVertex.hxx>
#include <BRepExtrema_DistShapeShape.hxx>
#include <BRepBuilderAPI_MakeWire.hxx>
#include <BRepBuilderAPI_Sewing.hxx>
#include <BRepGProp.hxx>
#include <BRepMesh_IncrementalMesh.hxx>
#include <BRepPrimAPI_MakeRevol.hxx>
#include <BRep_Builder.hxx>
#include <BRep_Tool.hxx>
#include <Bnd_Box.hxx>
#include <GProp_GProps.hxx>
#include <GeomAPI_Interpolate.hxx>
#include <GeomAPI_PointsToBSplineSurface.hxx>
#include <Geom_BSplineSurface.hxx>
#include <Geom_Surface.hxx>
#if FLANK_CAD_IGES
#include <IGESBasic_Name.hxx>
#include <IGESControl_Controller.hxx>
#include <IGESControl_Reader.hxx>
#include <IGESControl_Writer.hxx>
#include <IGESData_IGESEntity.hxx>
#endif
#include <IMeshTools_Parameters.hxx>
#include <Interface_InterfaceModel.hxx>
#include <Interface_Static.hxx>
#include <Message.hxx>
#include <Message_Messenger.hxx>
#include <Message_PrinterOStream.hxx>
#include <Poly_Triangulation.hxx>
#include <STEPControl_Controller.hxx>
#include <STEPControl_Reader.hxx>
#include <STEPControl_Writer.hxx>
#include <ShapeBuild_ReShape.hxx>
#include <ShapeUpgrade_FaceDivide.hxx>
#include <ShapeUpgrade_SplitSurfaceArea.hxx>
#include <StepBasic_Product.hxx>
#include <StepBasic_ProductDefinition.hxx>
#include <StepBasic_ProductDefinitionFormation.hxx>
#include <StepData_StepModel.hxx>
#include <Standard_Failure.hxx>
#include <TColStd_Array1OfInteger.hxx>
#include <TColStd_Array1OfReal.hxx>
#include <TColgp_Array2OfPnt.hxx>
#include <TCollection_ExtendedString.hxx>
#include <TCollection_HAsciiString.hxx>
#include <TColgp_HArray1OfPnt.hxx>
#include <TopExp.hxx>
#include <TopExp_Explorer.hxx>
#include <TopLoc_Location.hxx>
#include <TopTools_IndexedMapOfShape.hxx>
#include <TopoDS.hxx>
#include <TopoDS_Compound.hxx>
#include <TopoDS_Face.hxx>
#include <TransferBRep.hxx>
#include <TransferBRep_ShapeMapper.hxx>
#include <Transfer_FinderProcess.hxx>
#include <XSControl_TransferReader.hxx>
#include <XSControl_WorkSession.hxx>
#include <gp_Ax1.hxx>
#include <gp_Pln.hxx>


#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <mutex>
#include <sstream>

#include "io/encode.h"
#include "io/read_mesh.h"  // io::Error

namespace flank::io::cad_module {

struct Shape {
  TopoDS_Shape shape;
  TopTools_IndexedMapOfShape face_map;  // 1-based
  std::vector<double> area;             // per face, face_map's order, mm²
};

struct Surface {
  Handle(Geom_BSplineSurface) surface;
};

namespace {

namespace fs = std::filesystem;

[[noreturn]] void fail(const std::string& name, const std::string& problem) {
  throw Error(name + ": " + problem);
}

#if !FLANK_CAD_IGES
// io/cad.cpp opens the IGES build for every IGES file; this build never sees one.
[[noreturn]] void no_iges(const std::string& name) {
  fail(name, "IGES needs flank's IGES module (libflank_cad_iges.so); this is the STEP one");
}
#endif

// OCCT reports through a global messenger that prints to stdout; flank's messages are its own.
void quiet_occt() {
  static std::once_flag once;
  std::call_once(once, [] {
    const Handle(Message_Messenger)& messenger = Message::DefaultMessenger();
    messenger->RemovePrinters(STANDARD_TYPE(Message_PrinterOStream));
    STEPControl_Controller::Init();
#if FLANK_CAD_IGES
    IGESControl_Controller::Init();
#endif
  });
}

std::string what_of(const Standard_Failure& e) {
  const char* message = e.GetMessageString();
  std::string text = message && *message ? message : e.DynamicType()->Name();
  return one_line(text);
}

// Runs an OCCT step; an OCCT exception becomes io::Error("NAME: doing: message").
template <class F>
auto guarded(const std::string& name, const std::string& doing, F&& f) {
  try {
    return f();
  } catch (const Error&) {
    throw;
  } catch (const Standard_Failure& e) {
    fail(name, doing + ": " + what_of(e));
  } catch (const std::exception& e) {
    fail(name, doing + ": " + one_line(e.what()));
  }
}

Vec3 vec(const gp_Pnt& p) { return {p.X(), p.Y(), p.Z()}; }
gp_Pnt pnt(const Vec3& p) { return {p.x(), p.y(), p.z()}; }

std::string surface_kind(const TopoDS_Face& face) {
  switch (BRepAdaptor_Surface(face).GetType()) {
    case GeomAbs_Plane: return "plane";
    case GeomAbs_Cylinder: return "cylinder";
    case GeomAbs_Cone: return "cone";
    case GeomAbs_Sphere: return "sphere";
    case GeomAbs_Torus: return "torus";
    case GeomAbs_BezierSurface: return "bezier";
    case GeomAbs_BSplineSurface: return "bspline";
    case GeomAbs_SurfaceOfRevolution: return "revolution";
    case GeomAbs_SurfaceOfExtrusion: return "extrusion";
    case GeomAbs_OffsetSurface: return "offset";
    default: return "other";
  }
}

// Shapes with their names, in the order they are written or were read. Names travel as STEP
// product names and IGES entity names; OCCT's XCAF documents could carry them too, but bring
// 43 more libraries (the 3D viewer's, X11, images, fonts): 40% of the module's opening (85 ->
// 51 ms of CPU for a stub linked to each set; twenty-seventh part of issue 13, docs/performance-history.md).
using NamedShapes = std::vector<std::pair<TopoDS_Shape, std::string>>;

// A name as flank shows it: decoded as UTF-8 (OCCT's STEP reader converts the file's encoded
// strings to it; ASCII, as IGES names are, reads the same), one line, every character beyond
// ASCII a '?'.
std::string display_name(const Handle(TCollection_HAsciiString)& text) {
  if (text.IsNull()) return {};
  const TCollection_ExtendedString wide(text->ToCString(), /*isMultiByte=*/Standard_True);
  std::string out;
  for (int k = 1; k <= wide.Length(); ++k) {
    const auto c = static_cast<unsigned>(wide.Value(k));
    out += c < 0x80 ? static_cast<char>(c) : '?';
  }
  return one_line(out);
}

// A STEP root's name: its product's name, else the product's id (as a product without a name
// is named by CAD systems), else none.
std::string step_root_name(const Handle(Standard_Transient)& root) {
  const Handle(StepBasic_ProductDefinition) definition = Handle(StepBasic_ProductDefinition)::DownCast(root);
  if (definition.IsNull() || definition->Formation().IsNull()) return {};
  const Handle(StepBasic_Product) product = definition->Formation()->OfProduct();
  if (product.IsNull()) return {};
  if (!product->Name().IsNull() && product->Name()->UsefullLength() > 0) return display_name(product->Name());
  return display_name(product->Id());
}

#if FLANK_CAD_IGES
// An IGES root's name: its name property (406 form 15), else its short label.
std::string iges_root_name(const Handle(Standard_Transient)& root) {
  const Handle(IGESData_IGESEntity) entity = Handle(IGESData_IGESEntity)::DownCast(root);
  if (entity.IsNull() || !entity->HasName()) return {};
  return display_name(entity->NameValue());
}
#endif

// The roots the reader transferred, each with its shape and name, in the file's order.
NamedShapes transferred_roots(XSControl_Reader& reader, std::string (*name_of)(const Handle(Standard_Transient)&)) {
  const Handle(XSControl_TransferReader) transfer = reader.WS()->TransferReader();
  NamedShapes roots;
  for (int k = 1; k <= reader.NbRootsForTransfer(); ++k) {
    const Handle(Standard_Transient) root = reader.RootForTransfer(k);
    const TopoDS_Shape shape = transfer->ShapeResult(root);
    if (!shape.IsNull()) roots.emplace_back(shape, name_of(root));
  }
  return roots;
}

std::shared_ptr<const Shape> read(const std::string& path, bool step, std::vector<CadFace>& faces,
                                  std::vector<std::string>& names) {
  quiet_occt();
  auto impl = std::make_shared<Shape>();

  NamedShapes named;
  guarded(path, std::string("reading ") + (step ? "STEP" : "IGES"), [&] {
    // Read, then transfer: a file OCCT parses but that holds no shape has no faces.
    std::unique_ptr<XSControl_Reader> reader;
    std::string (*name_of)(const Handle(Standard_Transient)&) = step_root_name;
    if (step) {
      reader = std::make_unique<STEPControl_Reader>();
    } else {
#if FLANK_CAD_IGES
      reader = std::make_unique<IGESControl_Reader>();
      name_of = iges_root_name;
#else
      no_iges(path);
#endif
    }
    if (reader->ReadFile(path.c_str()) != IFSelect_RetDone)
      fail(path, std::string("not a readable ") + (step ? "STEP" : "IGES") + " file");
    reader->TransferRoots();
    named = transferred_roots(*reader, name_of);
    if (named.empty()) fail(path, std::string("no faces in this ") + (step ? "STEP" : "IGES") + " file (no shape to read)");
    return 0;
  });

  TopoDS_Compound all;
  BRep_Builder builder;
  builder.MakeCompound(all);
  for (const auto& [s, name] : named) builder.Add(all, s);
  impl->shape = all;
  TopExp::MapShapes(all, TopAbs_FACE, impl->face_map);
  const int n = impl->face_map.Extent();
  if (n == 0) fail(path, std::string("no faces in this ") + (step ? "STEP" : "IGES") + " file");
  names.assign(static_cast<std::size_t>(n), "");
  for (const auto& [s, name] : named)
    for (TopExp_Explorer e(s, TopAbs_FACE); e.More(); e.Next()) {
      const int index = impl->face_map.FindIndex(e.Current());
      if (index > 0 && names[index - 1].empty()) names[index - 1] = name;
    }
  guarded(path, "measuring faces", [&] {
    for (int i = 1; i <= n; ++i) {
      const TopoDS_Face& face = TopoDS::Face(impl->face_map(i));
      CadFace f;
      f.index = i;
      f.surface = surface_kind(face);
      GProp_GProps props;
      BRepGProp::SurfaceProperties(face, props);
      f.area = props.Mass();
      impl->area.push_back(f.area);
      Bnd_Box box;
      BRepBndLib::AddOptimal(face, box, /*useTriangulation=*/false, /*useShapeTolerance=*/false);
      if (!box.IsVoid()) {
        double x0, y0, z0, x1, y1, z1;
        box.Get(x0, y0, z0, x1, y1, z1);
        f.min = {x0, y0, z0};
        f.max = {x1, y1, z1};
      }
      if (!f.min.allFinite() || !f.max.allFinite() || !std::isfinite(f.area))
        fail(path, "face " + std::to_string(i) + " is unbounded or has non-finite geometry");
      faces.push_back(std::move(f));
    }
    return 0;
  });
  return impl;
}


// Face `face` in `pieces` pieces of its parameter range, each about square on the part (OCCT's
// split by number, which measures no area), sharing their new edges; the face itself when
// OCCT cannot split it.
TopoDS_Shape split(const TopoDS_Face& face, int pieces) {
  if (pieces < 2) return face;
  try {
    Handle(ShapeUpgrade_SplitSurfaceArea) grid = new ShapeUpgrade_SplitSurfaceArea();
    grid->NbParts() = pieces;
    Handle(ShapeBuild_ReShape) context = new ShapeBuild_ReShape();
    ShapeUpgrade_FaceDivide divide(face);
    divide.SetContext(context);
    divide.SetSplitSurfaceTool(grid);
    if (!divide.Perform()) return face;
    const TopoDS_Shape result = context->Apply(divide.Result());
    return result.IsNull() ? TopoDS_Shape(face) : result;
  } catch (const Standard_Failure&) {
    return face;
  }
}

void tessellate(const Shape& shape, const std::string& path, const std::vector<int>& faces, double sew,
                double deviation, bool parallel, std::vector<double>& xyz, std::vector<int>& triangles,
                double& measured) {
  measured = 0.0;
  guarded(path, "tessellating", [&] {
    // OCCT meshes one face on one thread, and a large face more slowly per triangle than its
    // pieces (the synthesised cone face of the CAD acceptance, 29k triangles: 0.30 s whole,
    // 0.15 s in 8 pieces on one thread, 0.08 s on two; a spline-cutter face of 750k
    // triangles: 28 s, 4.6 s on two). So the chosen faces are cut into some kPieces pieces
    // in all, a face its share by area, before they are sewn: the mesh is the same whatever
    // the thread count.
    constexpr int kPieces = 8;
    double total = 0.0;
    for (const int i : faces) total += shape.area[static_cast<std::size_t>(i - 1)];
    // Sewn, so that faces and pieces meeting along an edge share its points; a copy, the part
    // itself stays as read.
    BRepBuilderAPI_Sewing sewing(sew);
    for (const int i : faces) {
      const double share = total > 0 ? shape.area[static_cast<std::size_t>(i - 1)] / total : 0.0;
      sewing.Add(split(TopoDS::Face(shape.face_map(i)), static_cast<int>(std::lround(kPieces * share))));
    }
    sewing.Perform();
    TopoDS_Shape sewn = sewing.SewedShape();
    if (sewn.IsNull()) fail(path, "sewing the faces gave no shape");
    // Delabella, OCCT's other Delaunay triangulator, is many times faster than its default
    // (Watson) on B-spline faces, whose circle search grows faster than the mesh (a cutter of
    // tools.step: 11.5 s and 1.4 GB against 0.5 s and 47 MB, the same 14,499 nodes). On the
    // cone face of the CAD acceptance its triangles and chord deviation match Watson's; on
    // some faces its deviation is larger (a synthesised barrel face asked 1.17 µm: 11 µm,
    // Watson 3.9 µm in over ten times the time), which the caller measures and asks again or
    // refuses. A face it leaves bare gets Watson's mesh.
    IMeshTools_Parameters parameters;
    parameters.Deflection = deviation;
    parameters.Angle = 0.5;
    parameters.Relative = false;
    parameters.InParallel = parallel;  // faces on oneTBB's threads, within the command's limit
    parameters.MeshAlgo = IMeshTools_MeshAlgoType_Delabella;
    BRepMesh_IncrementalMesh mesher(sewn, parameters);
    if (!mesher.IsDone()) fail(path, "tessellation failed");
    for (TopExp_Explorer e(sewn, TopAbs_FACE); e.More(); e.Next()) {
      const TopoDS_Face& face = TopoDS::Face(e.Current());
      TopLoc_Location loc;
      if (!BRep_Tool::Triangulation(face, loc).IsNull()) continue;
      IMeshTools_Parameters watson = parameters;
      watson.MeshAlgo = IMeshTools_MeshAlgoType_Watson;
      BRepMesh_IncrementalMesh again(face, watson);  // meshes the face as it is made
    }
    for (TopExp_Explorer e(sewn, TopAbs_FACE); e.More(); e.Next()) {
      const TopoDS_Face& face = TopoDS::Face(e.Current());
      TopLoc_Location loc;
      const Handle(Poly_Triangulation) tri = BRep_Tool::Triangulation(face, loc);
      if (tri.IsNull()) continue;
      const gp_Trsf trsf = loc.Transformation();
      const int base = static_cast<int>(xyz.size() / 3);
      for (int k = 1; k <= tri->NbNodes(); ++k) {
        const gp_Pnt p = tri->Node(k).Transformed(trsf);
        xyz.insert(xyz.end(), {p.X(), p.Y(), p.Z()});
      }
      const bool reversed = face.Orientation() == TopAbs_REVERSED;
      BRepAdaptor_Surface surface(face);
      for (int k = 1; k <= tri->NbTriangles(); ++k) {
        int n1, n2, n3;
        tri->Triangle(k).Get(n1, n2, n3);
        if (reversed) std::swap(n2, n3);
        triangles.insert(triangles.end(), {base + n1 - 1, base + n2 - 1, base + n3 - 1});
        if (!tri->HasUVNodes()) continue;
        // The chord deviation: the surface at the triangle's centre and edge midpoints (in
        // the face's parameters) against the flat triangle there.
        const int node[3] = {n1, n2, n3};
        const double w[4][3] = {{1 / 3.0, 1 / 3.0, 1 / 3.0}, {0.5, 0.5, 0}, {0, 0.5, 0.5}, {0.5, 0, 0.5}};
        for (const auto& wk : w) {
          gp_XY uv(0, 0);
          gp_XYZ flat(0, 0, 0);
          for (int c = 0; c < 3; ++c) {
            uv += wk[c] * tri->UVNode(node[c]).XY();
            flat += wk[c] * tri->Node(node[c]).Transformed(trsf).XYZ();
          }
          const gp_Pnt on = surface.Value(uv.X(), uv.Y());
          measured = std::max(measured, on.Distance(gp_Pnt(flat)));
        }
      }
    }
    return 0;
  });
}

Vec3 face_point(const Shape& shape, const std::string& path, int index, double u, double v) {
  return guarded(path, "evaluating face " + std::to_string(index), [&] {
    const TopoDS_Face& face = TopoDS::Face(shape.face_map(index));
    const BRepAdaptor_Surface s(face, /*restriction=*/false);
    const double u0 = s.FirstUParameter(), u1 = s.LastUParameter();
    const double v0 = s.FirstVParameter(), v1 = s.LastVParameter();
    return vec(s.Value(u0 + u * (u1 - u0), v0 + v * (v1 - v0)));
  });
}

double distance(const Shape& shape, const std::string& path, const Vec3& p) {
  return guarded(path, "measuring a distance", [&] {
    BRepExtrema_DistShapeShape d(BRepBuilderAPI_MakeVertex(pnt(p)).Vertex(), shape.shape);
    if (!d.IsDone() || d.NbSolution() == 0) fail(path, "no distance from a point to the faces");
    return d.Value();
  });
}

// ---------------------------------------------------------------------------------------
// Writing

std::shared_ptr<const Surface> fit(const std::string& name, const Points& grid, int rows, int cols,
                                   double tolerance) {
  quiet_occt();
  if (rows < 4 || cols < 4 || grid.rows() != static_cast<Eigen::Index>(rows) * cols || !grid.allFinite())
    fail(name, "a B-spline surface needs a finite grid of at least 4 × 4 points");
  return guarded(name, "fitting a B-spline surface", [&] {
    TColgp_Array2OfPnt points(1, rows, 1, cols);
    for (int i = 0; i < rows; ++i)
      for (int j = 0; j < cols; ++j)
        points.SetValue(i + 1, j + 1, pnt(grid.row(static_cast<Eigen::Index>(i) * cols + j).transpose()));
    GeomAPI_PointsToBSplineSurface approx;
    if (tolerance > 0)
      approx.Init(points, Approx_IsoParametric, 3, 8, GeomAbs_C2, tolerance);
    else
      approx.Interpolate(points, Approx_IsoParametric);
    if (!approx.IsDone() || approx.Surface().IsNull()) fail(name, "no B-spline surface within the tolerance");
    auto impl = std::make_shared<Surface>();
    impl->surface = approx.Surface();
    return std::shared_ptr<const Surface>(std::move(impl));
  });
}

std::shared_ptr<const Surface> from_poles(const std::string& name, const Points& poles, int nu, int nv,
                                          const std::vector<double>& knots_u, const std::vector<double>& knots_v) {
  quiet_occt();
  if (nu < 4 || nv < 4 || poles.rows() != static_cast<Eigen::Index>(nu) * nv || !poles.allFinite() ||
      knots_u.size() != static_cast<std::size_t>(nu + 4) || knots_v.size() != static_cast<std::size_t>(nv + 4))
    fail(name, "a cubic B-spline surface needs at least 4 × 4 finite poles and clamped knots");
  // OCCT takes distinct knots with multiplicities.
  auto distinct = [](const std::vector<double>& knots, TColStd_Array1OfReal*& values, TColStd_Array1OfInteger*& mults) {
    std::vector<double> v;
    std::vector<int> m;
    for (const double k : knots) {
      if (!v.empty() && k == v.back()) {
        ++m.back();
      } else {
        v.push_back(k);
        m.push_back(1);
      }
    }
    values = new TColStd_Array1OfReal(1, static_cast<int>(v.size()));
    mults = new TColStd_Array1OfInteger(1, static_cast<int>(v.size()));
    for (std::size_t i = 0; i < v.size(); ++i) {
      values->SetValue(static_cast<int>(i + 1), v[i]);
      mults->SetValue(static_cast<int>(i + 1), m[i]);
    }
  };
  return guarded(name, "building a B-spline surface", [&] {
    TColgp_Array2OfPnt array(1, nu, 1, nv);
    for (int i = 0; i < nu; ++i)
      for (int j = 0; j < nv; ++j)
        array.SetValue(i + 1, j + 1, pnt(poles.row(static_cast<Eigen::Index>(i) * nv + j).transpose()));
    TColStd_Array1OfReal *ku = nullptr, *kv = nullptr;
    TColStd_Array1OfInteger *mu = nullptr, *mv = nullptr;
    distinct(knots_u, ku, mu);
    distinct(knots_v, kv, mv);
    const std::unique_ptr<TColStd_Array1OfReal> hold_ku(ku), hold_kv(kv);
    const std::unique_ptr<TColStd_Array1OfInteger> hold_mu(mu), hold_mv(mv);
    auto impl = std::make_shared<Surface>();
    impl->surface = new Geom_BSplineSurface(array, *ku, *kv, *mu, *mv, 3, 3);
    return std::shared_ptr<const Surface>(std::move(impl));
  });
}

Vec3 point(const Surface& s, double u, double v) {
  double u0, u1, v0, v1;
  s.surface->Bounds(u0, u1, v0, v1);
  return vec(s.surface->Value(u0 + u * (u1 - u0), v0 + v * (v1 - v0)));
}

void size(const Surface& s, int& poles_u, int& poles_v, int& degree_u, int& degree_v) {
  poles_u = s.surface->NbUPoles();
  poles_v = s.surface->NbVPoles();
  degree_u = s.surface->UDegree();
  degree_v = s.surface->VDegree();
}

#if FLANK_CAD_IGES
// `text` with every byte beyond ASCII replaced by `other` (IGES's names).
std::string ascii_only(std::string text, char other) {
  for (char& c : text)
    if (static_cast<unsigned char>(c) >= 0x80) c = other;
  return text;
}
#endif

// The bytes of the named shapes as STEP or IGES (by extension), written through a
// temporary file; io/cad.cpp moves them into place with write_file_atomic.
std::string document_bytes(const fs::path& path, const NamedShapes& shapes) {
  const std::string name = path.string();
  const std::string ext = lower_extension(path);
  const bool step = step_extension(ext);  // else IGES (io/cad.cpp checked)
  // OCCT writes to a path; the bytes go through flank's atomic writer so that the output set
  // stays all or nothing. The scratch file is private (mkstemp) and removed.
  std::string scratch_path =
      (fs::temp_directory_path() / (step ? "flank-cad-XXXXXX.step" : "flank-cad-XXXXXX.igs")).string();
  const int fd = mkstemps(scratch_path.data(), step ? 5 : 4);
  if (fd < 0) fail(name, "cannot create a scratch file in " + fs::temp_directory_path().string());
  ::close(fd);
  struct Remove {
    std::string p;
    ~Remove() { std::remove(p.c_str()); }
  } remove{scratch_path};
  guarded(name, std::string("writing ") + (step ? "STEP" : "IGES"), [&] {
    bool done = false;
    if (step) {
      Interface_Static::SetCVal("write.step.schema", "AP214IS");
      Interface_Static::SetCVal("write.step.unit", "MM");
      STEPControl_Writer writer;
      done = true;
      // Each shape its own product, named by its name (its id too): the one product each
      // transfer adds, found among the entities it added.
      for (const auto& [shape, shape_name] : shapes) {
        const int before = writer.Model()->NbEntities();
        if (writer.Transfer(shape, STEPControl_AsIs) != IFSelect_RetDone) {
          done = false;
          break;
        }
        const Handle(TCollection_HAsciiString) text = new TCollection_HAsciiString(shape_name.c_str());
        int named = 0;
        for (int k = before + 1; k <= writer.Model()->NbEntities(); ++k)
          if (const Handle(StepBasic_Product) product = Handle(StepBasic_Product)::DownCast(writer.Model()->Value(k));
              !product.IsNull()) {
            product->SetId(text);
            product->SetName(text);
            ++named;
          }
        if (named != 1) fail(name, "'" + one_line(shape_name) + "' became " + std::to_string(named) + " STEP products, not one");
      }
      done = done && writer.Write(scratch_path.c_str()) == IFSelect_RetDone;
    } else {
#if FLANK_CAD_IGES
      Interface_Static::SetCVal("write.iges.unit", "MM");
      Interface_Static::SetIVal("write.iges.brep.mode", 1);
      IGESControl_Writer writer;
      done = true;
      for (const auto& [shape, shape_name] : shapes) done = done && writer.AddShape(shape);
      // IGES names: the entity's short label (8 characters, right-aligned; the first 8 of a
      // longer name) and the whole name in a name property (entity 406, form 15).
      const Handle(Transfer_FinderProcess) finder = writer.TransferProcess();
      for (const auto& [shape, shape_name] : shapes) {
        Handle(IGESData_IGESEntity) entity;
        if (!done || !finder->FindTypedTransient(TransferBRep::ShapeMapper(finder, shape),
                                                 STANDARD_TYPE(IGESData_IGESEntity), entity))
          continue;
        const std::size_t shown = std::min<std::size_t>(shape_name.size(), 8);
        const std::string label = std::string(8 - shown, ' ') + ascii_only(shape_name, '?').substr(0, shown);
        entity->SetLabel(new TCollection_HAsciiString(label.c_str()));
        const Handle(IGESBasic_Name) long_name = new IGESBasic_Name;
        long_name->Init(1, new TCollection_HAsciiString(ascii_only(shape_name, '_').c_str()));
        entity->AddProperty(long_name);
        writer.AddEntity(long_name);
      }
      writer.ComputeModel();
      done = done && writer.Write(scratch_path.c_str());
#else
      no_iges(name);
#endif
    }
    if (!done) fail(name, "OCCT could not write the file");
    return 0;
  });
  std::ifstream in(scratch_path, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  if (!in) fail(name, "cannot read back the scratch file");
  std::string text = bytes.str();
  // Headers carry the scratch file's name and the time of writing: the output's own name and
  // a fixed stamp keep the bytes deterministic.
  if (step) {
    const std::size_t at = text.find("FILE_NAME(");
    const std::size_t q1 = at == std::string::npos ? at : text.find('\'', at);
    const std::size_t q2 = q1 == std::string::npos ? q1 : text.find('\'', q1 + 1);
    const std::size_t q3 = q2 == std::string::npos ? q2 : text.find('\'', q2 + 1);
    const std::size_t q4 = q3 == std::string::npos ? q3 : text.find('\'', q3 + 1);
    if (q4 != std::string::npos) {
      text.replace(q3, q4 - q3 + 1, "'1970-01-01T00:00:00'");
      text.replace(q1, q2 - q1 + 1, "'" + one_line(path.filename().string()) + "'");
    }
  } else {
    // The global section (column 73 'G') holds the file name and two dates "15HYYYYMMDD.HHNNSS".
    std::size_t line = 0;
    while (line < text.size()) {
      std::size_t end = text.find('\n', line);
      if (end == std::string::npos) end = text.size();
      if (end - line >= 73 && text[line + 72] == 'G') {
        for (std::size_t at = text.find("15H", line); at != std::string::npos && at + 18 <= end;
             at = text.find("15H", at + 3)) {
          const std::string stamp = text.substr(at + 3, 15);
          if (stamp.size() == 15 && stamp[8] == '.' &&
              std::all_of(stamp.begin(), stamp.begin() + 8, [](char c) { return c >= '0' && c <= '9'; }))
            text.replace(at + 3, 15, "19700101.000000");
        }
        const std::size_t scratch_at = text.find(scratch_path, line);
        if (scratch_at != std::string::npos && scratch_at < end) fail(name, "IGES header names the scratch file");
      }
      line = end + 1;
    }
  }
  return text;
}

std::string surfaces_file(const std::string& path, const std::vector<std::pair<std::string, const Surface*>>& surfaces) {
  quiet_occt();
  const std::string& name = path;
  NamedShapes shapes;
  guarded(name, "building faces", [&] {
    for (const auto& [face_name, surface] : surfaces) {
      BRepBuilderAPI_MakeFace face(surface->surface, 1e-7);
      if (!face.IsDone()) fail(name, "cannot make a face of surface '" + one_line(face_name) + "'");
      shapes.emplace_back(face.Face(), face_name);
    }
    return 0;
  });
  return document_bytes(path, shapes);
}

std::string solids_file(const std::string& path, const std::vector<RevolvedSolid>& solids) {
  quiet_occt();
  const std::string& name = path;
  NamedShapes shapes;
  guarded(name, "building solids", [&] {
    for (const RevolvedSolid& s : solids) {
      const auto n = s.meridian.size();
      if (n < 2) fail(name, "solid '" + one_line(s.name) + "' has fewer than 2 meridian points");
      for (std::size_t k = 0; k < n; ++k) {
        if (!s.meridian[k].allFinite() || s.meridian[k].y() <= 0 ||
            (k > 0 && !(s.meridian[k].x() > s.meridian[k - 1].x())))
          fail(name, "solid '" + one_line(s.name) + "': meridian point " + std::to_string(k) +
                         " is not finite, not off the axis, or not past the previous one");
      }
      const Vec3 axis = s.axis.normalized();
      // A unit vector normal to the axis: the meridian's radial direction.
      Vec3 radial = axis.unitOrthogonal();
      auto at = [&](double x, double r) { return pnt(s.origin + x * axis + r * radial); };
      // The side: an interpolating cubic through the meridian points (exact for a line).
      Handle(TColgp_HArray1OfPnt) side = new TColgp_HArray1OfPnt(1, static_cast<int>(n));
      for (std::size_t k = 0; k < n; ++k) side->SetValue(static_cast<int>(k + 1), at(s.meridian[k].x(), s.meridian[k].y()));
      GeomAPI_Interpolate interpolate(side, /*periodic=*/false, 1e-9);
      interpolate.Perform();
      if (!interpolate.IsDone()) fail(name, "solid '" + one_line(s.name) + "': cannot interpolate the meridian");
      const gp_Pnt tip_axis = at(s.meridian.front().x(), 0), end_axis = at(s.meridian.back().x(), 0);
      BRepBuilderAPI_MakeWire wire;
      wire.Add(BRepBuilderAPI_MakeEdge(tip_axis, side->Value(1)).Edge());
      wire.Add(BRepBuilderAPI_MakeEdge(interpolate.Curve()).Edge());
      wire.Add(BRepBuilderAPI_MakeEdge(side->Value(static_cast<int>(n)), end_axis).Edge());
      wire.Add(BRepBuilderAPI_MakeEdge(end_axis, tip_axis).Edge());
      if (!wire.IsDone()) fail(name, "solid '" + one_line(s.name) + "': the meridian does not close");
      BRepBuilderAPI_MakeFace profile(wire.Wire(), /*onlyPlane=*/true);
      if (!profile.IsDone()) fail(name, "solid '" + one_line(s.name) + "': the meridian is not planar");
      BRepPrimAPI_MakeRevol revol(profile.Face(), gp_Ax1(pnt(s.origin), gp_Dir(axis.x(), axis.y(), axis.z())));
      revol.Build();
      if (!revol.IsDone()) fail(name, "solid '" + one_line(s.name) + "': the revolution failed");
      shapes.emplace_back(revol.Shape(), s.name);
    }
    return 0;
  });
  return document_bytes(path, shapes);
}

// What every first translation would otherwise do on the command's path: the translators'
// set-up (quiet_occt) and a STEP writer's session with its resources, made once here, on the
// thread that opens the module (io/cad.cpp: beside the command's own work). Nothing may
// escape the module's entry: should Open CASCADE fail here, the translation that needs it
// fails again later, where its error names the file.
void warm_up() noexcept {
  try {
    quiet_occt();
    const STEPControl_Writer writer;
  } catch (...) {
  }
}

const Api kApi = [] {
  Api api;
  api.version = kVersion;
  api.read = read;
  api.tessellate = tessellate;
  api.face_point = face_point;
  api.distance = distance;
  api.fit = fit;
  api.from_poles = from_poles;
  api.point = point;
  api.size = size;
  api.surfaces_file = surfaces_file;
  api.solids_file = solids_file;
  return api;
}();

}  // namespace

}  // namespace flank::io::cad_module

const flank::io::cad_module::Api* flank_cad_module() {
  flank::io::cad_module::warm_up();
  return &flank::io::cad_module::kApi;
}
