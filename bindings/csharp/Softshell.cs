// softshell's C ABI (softshell_c.h, softshell_embedded_c.h) for C#: P/Invoke declarations of every
// function, the structs with the C layouts, and two helpers (Check, Utf8). Copy this file into a
// Unity project (Assets/Scripts) next to libsoftshell_plugin in Assets/Plugins; it needs
// "Allow 'unsafe' code" for EmbeddedOptions' fixed host buffer (mcs/csc: -unsafe).
//
// Conventions, as in the C header:
//  - Handles are IntPtr (generation-checked ids; IntPtr.Zero is NULL). Release each with its
//    ss_*_destroy; a destroyed handle is reported as Status.InvalidArgument, never a crash.
//  - Every function returns a Status; after a failure ss_last_error_message() (LastError()) says
//    what was wrong. Check(status) throws a SoftshellException carrying both.
//  - Arrays go in and out as blittable managed arrays (double[], int[], float[]), pinned by the
//    marshaller for the call, no copies. Output buffers: pass (array, capacity in items, out count);
//    (null, 0, out count) only asks for the count.
//  - Strings in are NUL-terminated UTF-8 byte arrays (Utf8("...")); strings out are IntPtr to
//    static or thread-local storage (Utf8(IntPtr)).
//  - Units: metres, newtons, pascals. Unity and Unreal are left-handed: flip one axis (e.g. z)
//    of every position, force and ray going in and coming out.
//  - Nothing here blocks a frame: deform with ss_session_deform_begin, poll ss_deformation_poll
//    once a frame, read with ss_deformation_read.
//
// The struct sizes are checked against the C compiler's (static_asserts in the C ABI's sources and
// the C tests; Marshal.SizeOf in tests/csharp).

using System;
using System.Runtime.InteropServices;
using System.Text;

namespace Softshell
{
    public enum Status : int
    {
        Ok = 0,
        InvalidArgument = 1,        // malformed input: NULL, out of range, NaN, a destroyed handle
        Unprocessable = 2,          // well-formed but unusable: undetermined system, bad material
        NotFound = 3,               // unknown geometry or result
        PayloadTooLarge = 4,
        UnsupportedMediaType = 5,
        NotAcceptable = 6,
        ResourceExhausted = 7,      // out of memory or over a configured limit
        Unavailable = 8,            // server unreachable, timed out or shutting down
        Cancelled = 9,
        IoError = 10,               // a file could not be read or written
        Internal = 11,              // a bug in softshell; please report it
        Conflict = 12,              // contradicts other clients' holds (HTTP 409)
        Gone = 13,                  // no longer kept: a result dropped by retention, a deleted geometry (HTTP 410)
        BufferTooSmall = 100,       // capacity below the count
        NotReady = 101,             // an asynchronous operation has not finished
    }

    public enum LogLevel : int { Debug = 0, Info = 1, Warning = 2, Error = 3, Off = 4 }

    public enum GeometryState : int { Precomputing = 0, Ready = 1, Failed = 2 }

    public class SoftshellException : Exception
    {
        public readonly Status Status;
        public SoftshellException(Status status, string message) : base(message) { Status = status; }
    }

    [StructLayout(LayoutKind.Sequential)]
    public struct Vec3
    {
        public double x, y, z;
        public Vec3(double x, double y, double z) { this.x = x; this.y = y; this.z = z; }
    }

    /// <summary>Quaternion x, y, z, w (as Unity's Quaternion and Unreal's FQuat).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct Quat
    {
        public double x, y, z, w;
        public static readonly Quat Identity = new Quat { w = 1 };
    }

    [StructLayout(LayoutKind.Sequential)]
    public struct Pose
    {
        public Vec3 position;
        public Quat orientation;
    }

    /// <summary>A point of the limit surface: control face, sub-face (0 for quads) and (u, v).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct SurfacePoint
    {
        public int face;
        public int subface;
        public double u, v;
    }

    /// <summary>E (Pa), Poisson's ratio, thickness (m), density (kg/m^3).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct Material
    {
        public double youngs_modulus;
        public double poisson_ratio;
        public double thickness;
        public double density;
    }

    /// <summary>A content-derived geometry id (16 opaque bytes; ss_geom_id_to_hex prints it).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct GeomId
    {
        public ulong bytes0_7, bytes8_15;
    }

    [StructLayout(LayoutKind.Sequential)]
    public struct Ray
    {
        public Vec3 origin;
        public Vec3 direction;
        public double t_min;
        public double t_max;  // double.PositiveInfinity for an unbounded ray
    }

    [StructLayout(LayoutKind.Sequential)]
    public struct LimitSample
    {
        public Vec3 position, du, dv, normal;
    }

    [StructLayout(LayoutKind.Sequential)]
    public struct Pick
    {
        public int triangle;
        public int status;              // 0 converged, 1 at boundary, 2 not converged
        public SurfacePoint estimate;
        public SurfacePoint point;
        public Vec3 position;
        public Vec3 normal;
        public Vec3 du;
        public Vec3 dv;
        public double t;
        public double distance_to_ray;
        public double triangle_t;
        public int iterations;
        public int face_crossings;
    }

    [StructLayout(LayoutKind.Sequential)]
    public struct GrabOptions
    {
        public int follow_rotation;
        public int constrain_tangents;
    }

    [StructLayout(LayoutKind.Sequential)]
    public struct FloorOptions
    {
        public double tolerance;
        public int normal_only;
        public int snap;
    }

    [StructLayout(LayoutKind.Sequential)]
    public struct RemoteOptions
    {
        public int connect_timeout_ms;
        public int request_timeout_ms;
        public int binary;
        public int async_threads;
        /// <summary>NUL-terminated UTF-8 access token (a server's --auth-token-file), or IntPtr.Zero
        /// for none; copied by ss_session_create_remote, so the caller frees it afterwards (e.g.
        /// Marshal.StringToCoTaskMemUTF8 / Marshal.FreeCoTaskMem).</summary>
        public IntPtr auth_token;
    }

    [StructLayout(LayoutKind.Sequential)]
    public struct GeometryStatus
    {
        public GeometryState status;
        public int num_vertices;
        public int num_faces;
        public uint num_results;
        public double progress;        // precomputation progress in [0, 1]
    }

    /// <summary>Stress state at one surface point (local frame: e1 along du, e3 the normal).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct StressSample
    {
        public SurfacePoint point;
        public Vec3 position;          // rest limit position
        public Vec3 membrane_force;    // n11, n22, n12 (N/m)
        public Vec3 bending_moment;    // m11, m22, m12 (N m / m)
        public double von_mises_top;   // Pa, at +t/2
        public double von_mises_bottom; // Pa, at -t/2
    }

    /// <summary>Options of the in-process server (blittable: the host is a fixed 64-byte buffer, data_dir
    /// a pointer to UTF-8 the caller owns, e.g. from Marshal.StringToCoTaskMemUTF8 or a pinned Native.Utf8
    /// array).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public unsafe struct EmbeddedOptions
    {
        public const int HostCapacity = 64;
        public int worker_threads;
        public int cache_mb;
        public int listen;             // != 0: also serve the HTTP API on http_host:http_port
        public int http_port;          // 0: any free port
        public fixed byte http_host[HostCapacity];
        public int keep_results;       // results kept per geometry; 0: the default (1000), -1: no count limit
        public int result_budget_mb;   // MiB of results kept per geometry; 0: no byte limit
        public IntPtr data_dir;        // NUL-terminated UTF-8 directory of a persistent store (copied in by
                                       // ss_session_create_embedded; free it after); IntPtr.Zero: memory only

        /// <summary>Sets http_host (UTF-8, NUL-terminated, at most 63 bytes).</summary>
        public void SetHttpHost(string host)
        {
            byte[] bytes = Encoding.UTF8.GetBytes(host);
            if (bytes.Length >= HostCapacity) throw new ArgumentException("host longer than 63 bytes", "host");
            fixed (byte* p = http_host)
            {
                for (int i = 0; i < HostCapacity; ++i) p[i] = i < bytes.Length ? bytes[i] : (byte)0;
            }
        }
    }

    /// <summary>Receives log messages (message: UTF-8, valid during the call). Called from
    /// softshell's threads: keep the delegate alive (a static field) while installed; under IL2CPP
    /// the target must be a static method marked [AOT.MonoPInvokeCallback(typeof(LogCallback))].</summary>
    [UnmanagedFunctionPointer(CallingConvention.Cdecl)]
    public delegate void LogCallback(int level, IntPtr message, IntPtr userData);

    public static class Native
    {
        /// <summary>libsoftshell_plugin.so / softshell_plugin.dll / libsoftshell_plugin.dylib.</summary>
        public const string Lib = "softshell_plugin";
        public const uint AbiVersion = 4;
        public const int Mask_X = 1, Mask_Y = 2, Mask_Z = 4, Mask_All = 7;
        public const int ForceTransferSubdivide = 0, ForceTransferVirtualWork = 1;
        public const int BoundaryEdgeAndCorner = 0, BoundaryNone = 1;
        public const int FeedConnecting = 0, FeedLive = 1, FeedFailed = 2;
        public const int ModelLinear = 0, ModelNonlinear = 1;

        // ---- helpers -----------------------------------------------------------------------

        /// <summary>NUL-terminated UTF-8 for string arguments (null stays null).</summary>
        public static byte[] Utf8(string s)
        {
            if (s == null) return null;
            byte[] b = Encoding.UTF8.GetBytes(s);
            Array.Resize(ref b, b.Length + 1);
            return b;
        }

        /// <summary>A C string returned by softshell (IntPtr.Zero gives null).</summary>
        public static string Utf8(IntPtr p)
        {
            if (p == IntPtr.Zero) return null;
            int n = 0;
            while (Marshal.ReadByte(p, n) != 0) ++n;
            byte[] b = new byte[n];
            Marshal.Copy(p, b, 0, n);
            return Encoding.UTF8.GetString(b);
        }

        public static string LastError() { return Utf8(ss_last_error_message()); }

        /// <summary>Throws SoftshellException unless status is Ok.</summary>
        public static void Check(Status status)
        {
            if (status != Status.Ok) throw new SoftshellException(status, LastError());
        }

        // ---- version, status, log ----------------------------------------------------------

        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern IntPtr ss_version();
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern uint ss_version_number();
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern uint ss_abi_version();
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern IntPtr ss_last_error_message();
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern IntPtr ss_status_name(Status status);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_set_log_callback(LogCallback callback, IntPtr userData, LogLevel minLevel);

        // ---- materials ---------------------------------------------------------------------

        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_material_default(out Material m);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern Status ss_material_check(ref Material m);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_material_preset(byte[] name, double thickness, out Material m);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern int ss_material_preset_count();
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_material_preset_at(int index, out IntPtr name, out IntPtr description, out Material m,
                                                          out double yieldStrength);

        // ---- option defaults ---------------------------------------------------------------

        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_grab_options_default(out GrabOptions o);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_floor_options_default(out FloorOptions o);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_remote_options_default(out RemoteOptions o);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_embedded_options_default(out EmbeddedOptions o);

        // ---- control mesh ------------------------------------------------------------------

        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_mesh_create(double[] positionsXyz, int numVertices, int[] faceSizes, int numFaces,
                                                   int[] faceIndices, int numFaceIndices, out IntPtr mesh);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern Status ss_mesh_read_obj(byte[] path, out IntPtr mesh);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern Status ss_mesh_write_obj(IntPtr mesh, byte[] path);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_mesh_destroy(IntPtr mesh);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_mesh_counts(IntPtr mesh, out int numVertices, out int numFaces);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_mesh_positions(IntPtr mesh, double[] outXyz, int capacity, out int count);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_mesh_set_positions(IntPtr mesh, double[] positionsXyz, int count);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_mesh_faces(IntPtr mesh, int[] outSizes, int sizesCapacity, out int numFaces,
                                                  int[] outIndices, int indicesCapacity, out int numIndices);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern Status ss_mesh_set_boundary(IntPtr mesh, int boundary);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_mesh_add_crease(IntPtr mesh, int v0, int v1, float sharpness);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern Status ss_mesh_validate(IntPtr mesh);

        // ---- limit surface -----------------------------------------------------------------

        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern Status ss_evaluator_create(IntPtr mesh, out IntPtr evaluator);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_evaluator_destroy(IntPtr evaluator);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_evaluator_num_subfaces(IntPtr evaluator, int face, out int count);
        /// <summary>positionsXyz null and count 0: the rest shape.</summary>
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_evaluator_evaluate(IntPtr evaluator, ref SurfacePoint point, double[] positionsXyz, int count,
                                                          out LimitSample sample);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_evaluator_stencil(IntPtr evaluator, ref SurfacePoint point, int[] outIndices, double[] outPosition,
                                                         double[] outDu, double[] outDv, int capacity, out int count);

        // ---- tessellation and picking ------------------------------------------------------

        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_tessellation_create(IntPtr evaluator, int level, out IntPtr tessellation);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_tessellation_destroy(IntPtr tessellation);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_tessellation_counts(IntPtr tessellation, out int numVertices, out int numTriangles);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_tessellation_vertices(IntPtr tessellation, float[] outXyz, int capacity, out int count);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_tessellation_normals(IntPtr tessellation, float[] outXyz, int capacity, out int count);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_tessellation_triangles(IntPtr tessellation, int[] outIndices, int capacity, out int count);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_tessellation_update(IntPtr tessellation, double[] positionsXyz, int count);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern Status ss_picker_create(IntPtr tessellation, out IntPtr picker);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_picker_destroy(IntPtr picker);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern Status ss_picker_refit(IntPtr picker);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_picker_pick(IntPtr picker, ref Ray ray, int refine, out Pick pick, out int hit);

        // ---- requests and interaction ------------------------------------------------------

        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern Status ss_request_create(out IntPtr request);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_request_destroy(IntPtr request);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern Status ss_request_clear(IntPtr request);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_request_add_vertex_constraint(IntPtr request, int index, uint mask, ref Vec3 displacement);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_request_add_force(IntPtr request, int index, ref Vec3 force);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_request_add_surface_force(IntPtr request, ref SurfacePoint point, ref Vec3 force);
        /// <summary>duDisplacement / dvDisplacement: IntPtr.Zero for none (or use the overload).</summary>
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_request_add_limit_constraint(IntPtr request, ref SurfacePoint point, ref Vec3 displacement,
                                                                    IntPtr duDisplacement, IntPtr dvDisplacement);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_request_add_limit_constraint(IntPtr request, ref SurfacePoint point, ref Vec3 displacement,
                                                                    ref Vec3 duDisplacement, ref Vec3 dvDisplacement);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_request_add_lagrange_constraint(IntPtr request, int[] indices, Vec3[] coefficients, int count,
                                                                       ref Vec3 values);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_request_set_surface_load(IntPtr request, ref Vec3 loadPerArea);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern Status ss_request_set_pressure(IntPtr request, double pressure);
        /// <summary>model: ModelLinear (the default) or ModelNonlinear (large displacements and rotations).</summary>
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern Status ss_request_set_model(IntPtr request, int model);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern Status ss_request_model(IntPtr request, out int model);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_request_add_floor(IntPtr request, IntPtr tessellation, ref Vec3 planePoint, ref Vec3 planeNormal,
                                                         ref FloorOptions options, out int points, out int fixesRigidMotion);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_request_counts(IntPtr request, out int vertexConstraints, out int lagrangeConstraints,
                                                      out int forces, out int limitConstraints, out int surfaceForces);
        /// <summary>currentXyz null and count 0: the rest shape.</summary>
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_grab_begin(IntPtr evaluator, ref SurfacePoint point, double[] currentXyz, int count, ref Pose hand,
                                                  ref GrabOptions options, out IntPtr grab);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_grab_destroy(IntPtr grab);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_grab_target(IntPtr grab, ref Pose hand, out Vec3 target);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_request_add_grab(IntPtr request, IntPtr grab, ref Pose hand);

        // ---- levels of detail --------------------------------------------------------------

        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_refinement_create(IntPtr coarse, int levels, out IntPtr refinement);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_refinement_destroy(IntPtr refinement);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_refinement_fine_mesh(IntPtr refinement, out IntPtr mesh);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_refinement_fine_point(IntPtr refinement, ref SurfacePoint coarsePoint, out SurfacePoint finePoint);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_refinement_refine_positions(IntPtr refinement, double[] coarseXyz, int count, double[] outFineXyz,
                                                                   int capacity, out int outCount);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_refinement_request_to_fine(IntPtr refinement, IntPtr coarseRequest, int forceTransfer,
                                                                  out IntPtr fineRequest);

        // ---- sessions ----------------------------------------------------------------------

        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_session_create_remote(byte[] url, ref RemoteOptions options, out IntPtr session);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_session_create_embedded(ref EmbeddedOptions options, out IntPtr session);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_session_embedded_port(IntPtr session, out int port);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_session_destroy(IntPtr session);
        /// <summary>outHex: at least 33 bytes (32 hex digits and NUL).</summary>
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_geom_id_to_hex(ref GeomId id, byte[] outHex, int capacity);
        /// <summary>nameSpace: null for the default namespace.</summary>
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_session_upload(IntPtr session, IntPtr mesh, ref Material material, byte[] nameSpace, out GeomId id,
                                                      out int created);
        /// <summary>Deletes the geometry and everything kept for it; NotFound for an unknown one. An upload of
        /// the same content later continues its result ids. Blocks for one request.</summary>
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_session_remove_geometry(IntPtr session, ref GeomId id);
        /// <summary>Blocks until solved: for tools and tests; a frame loop uses ss_session_deform_begin.</summary>
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_session_deform(IntPtr session, ref GeomId id, IntPtr request, out uint resId, double[] outXyz,
                                                      int capacity, out int count);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_session_deform_begin(IntPtr session, ref GeomId id, IntPtr request, out IntPtr operation);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern Status ss_deformation_poll(IntPtr operation, out int ready);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_deformation_wait(IntPtr operation, int timeoutMs, out int ready);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_deformation_read(IntPtr operation, out uint resId, double[] outXyz, int capacity, out int count);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_deformation_read_model(IntPtr operation, out int model, out int iterations, out double residual);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_deformation_destroy(IntPtr operation);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_session_latest_result(IntPtr session, ref GeomId id, uint have, int waitMs, out int hasNew,
                                                             out uint resId, double[] outXyz, int capacity, out int count);
        /// <summary>outError: null/0, or a byte buffer for the failure reason (UTF-8, NUL-terminated).</summary>
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_session_geometry_status(IntPtr session, ref GeomId id, out GeometryStatus status, byte[] outError,
                                                               int errorCapacity);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_session_limit_comb(IntPtr session, ref GeomId id, ref SurfacePoint point, int[] outIndices,
                                                          double[] outPosition, double[] outDu, double[] outDv, int capacity, out int count);

        /// <summary>level 1..4 (tessellation vertices) with points null/0, or level 0 with points.</summary>
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_session_stresses(IntPtr session, ref GeomId id, uint resId, int level, SurfacePoint[] points,
                                                        int numPoints, double yieldStrength, out IntPtr field);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_stress_field_samples(IntPtr field, [Out] StressSample[] outSamples, int capacity, out int count);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_stress_field_max(IntPtr field, out StressSample max, out int exceedsYield);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_stress_field_destroy(IntPtr field);

        // ---- holds and events (PROTOCOL.md version 2) --------------------------------------

        /// <summary>holdId: 1 to 64 characters of [A-Za-z0-9._-] (Utf8("...")); ttlMs 1..600000. Returns at
        /// once: poll ss_hold_put_poll once a frame, then ss_hold_put_read.</summary>
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_session_put_hold_begin(IntPtr session, ref GeomId id, byte[] holdId, IntPtr request, int ttlMs,
                                                              out IntPtr operation);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern Status ss_hold_put_poll(IntPtr operation, out int ready);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_hold_put_read(IntPtr operation, out uint resId, out ulong version, double[] outXyz, int capacity,
                                                     out int count);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_hold_put_read_model(IntPtr operation, out int model, out int iterations, out double residual);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_hold_put_destroy(IntPtr operation);
        /// <summary>Blocks for one request: call it off the frame loop, or when the grab ends.</summary>
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_session_release_hold(IntPtr session, ref GeomId id, byte[] holdId, out uint resId);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_session_subscribe(IntPtr session, ref GeomId id, uint after, out IntPtr subscription);
        /// <summary>Never blocks; latest wins (a slow reader skips to the newest result).</summary>
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_subscription_poll(IntPtr subscription, out int hasNew, out uint resId, double[] outXyz, int capacity,
                                                         out int count);
        /// <summary>state: FeedConnecting, FeedLive or FeedFailed.</summary>
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        public static extern Status ss_subscription_state(IntPtr subscription, out int state);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] public static extern void ss_subscription_destroy(IntPtr subscription);
    }
}
