// The Unity path, run: a C# program loads libsoftshell_plugin (the one file, beside the program as
// in Assets/Plugins) through bindings/csharp/Softshell.cs, starts the in-process server, uploads a
// plate, polls its precomputation, deforms it asynchronously as a frame loop would, and reads the
// positions back. Checks the physics it can (linearity, symmetry, constraints met) and the
// binding's layouts. Exit code 0 = every check passed.

using System;
using System.Runtime.InteropServices;
using System.Threading;
using Softshell;

static class SoftshellSmoke
{
    static int checks = 0, failures = 0;

    static void Check(bool ok, string what)
    {
        ++checks;
        if (!ok)
        {
            ++failures;
            Console.Error.WriteLine("CHECK failed: " + what + " (last error: " + Native.LastError() + ")");
        }
    }

    static int precomputeLogs = 0;
    static readonly LogCallback logCallback = OnLog;  // kept alive while installed
    static void OnLog(int level, IntPtr message, IntPtr userData)
    {
        if (Native.Utf8(message).Contains("precomputing geometry")) Interlocked.Increment(ref precomputeLogs);
    }

    const int N = 8, NV = (N + 1) * (N + 1);

    // A flat N x N plate over [0, 1]^2 at z = 0.
    static IntPtr Plate()
    {
        var xyz = new double[3 * NV];
        var sizes = new int[N * N];
        var indices = new int[4 * N * N];
        for (int j = 0; j <= N; ++j)
            for (int i = 0; i <= N; ++i)
            {
                xyz[3 * (j * (N + 1) + i)] = (double)i / N;
                xyz[3 * (j * (N + 1) + i) + 1] = (double)j / N;
            }
        for (int j = 0; j < N; ++j)
            for (int i = 0; i < N; ++i)
            {
                int f = j * N + i;
                sizes[f] = 4;
                indices[4 * f] = j * (N + 1) + i;
                indices[4 * f + 1] = j * (N + 1) + i + 1;
                indices[4 * f + 2] = (j + 1) * (N + 1) + i + 1;
                indices[4 * f + 3] = (j + 1) * (N + 1) + i;
            }
        IntPtr mesh;
        Native.Check(Native.ss_mesh_create(xyz, NV, sizes, N * N, indices, 4 * N * N, out mesh));
        return mesh;
    }

    // Clamped along x = 0 (two columns of control points), a downward force on every control
    // point of the free edge x = 1.
    static IntPtr Cantilever(double force)
    {
        IntPtr request;
        Native.Check(Native.ss_request_create(out request));
        var zero = new Vec3(0, 0, 0);
        var f = new Vec3(0, 0, -force);
        for (int j = 0; j <= N; ++j)
        {
            for (int i = 0; i < 2; ++i) Native.Check(Native.ss_request_add_vertex_constraint(request, j * (N + 1) + i, Native.Mask_All, ref zero));
            Native.Check(Native.ss_request_add_force(request, j * (N + 1) + N, ref f));
        }
        return request;
    }

    // The stresses of result resId at the level-1 tessellation's vertices (size query, then read).
    static StressSample[] Stresses(IntPtr session, GeomId id, uint resId)
    {
        IntPtr field;
        Native.Check(Native.ss_session_stresses(session, ref id, resId, 1, null, 0, 0.0, out field));
        int count;
        Native.Check(Native.ss_stress_field_samples(field, null, 0, out count));
        var samples = new StressSample[count];
        Native.Check(Native.ss_stress_field_samples(field, samples, count, out count));
        StressSample max;
        int exceeds;
        Native.Check(Native.ss_stress_field_max(field, out max, out exceeds));
        Check(exceeds == 0 && max.von_mises_top >= 0, "no yield strength given: nothing flagged");
        Native.ss_stress_field_destroy(field);
        return samples;
    }

    // Deforms without blocking: one poll per "frame", as a game loop does.
    static double[] DeformAsync(IntPtr session, GeomId id, IntPtr request, out int frames)
    {
        IntPtr op;
        Native.Check(Native.ss_session_deform_begin(session, ref id, request, out op));
        int ready = 0;
        frames = 0;
        while (ready == 0 && frames < 100000)
        {
            Native.Check(Native.ss_deformation_poll(op, out ready));
            if (ready == 0) { ++frames; Thread.Sleep(1); }
        }
        uint resId;
        int count;
        Check(Native.ss_deformation_read(op, out resId, null, 0, out count) == Status.Ok && count == NV, "size query");
        var xyz = new double[3 * count];
        Native.Check(Native.ss_deformation_read(op, out resId, xyz, count, out count));
        Native.ss_deformation_destroy(op);
        return xyz;
    }

    static int Main()
    {
        // The binding's layouts are the C compiler's (the same numbers as the C static_asserts).
        Check(Marshal.SizeOf(typeof(Vec3)) == 24 && Marshal.SizeOf(typeof(Pose)) == 56, "Vec3/Pose size");
        Check(Marshal.SizeOf(typeof(SurfacePoint)) == 24 && Marshal.SizeOf(typeof(Material)) == 32, "SurfacePoint/Material size");
        Check(Marshal.SizeOf(typeof(GeomId)) == 16 && Marshal.SizeOf(typeof(Ray)) == 64, "GeomId/Ray size");
        Check(Marshal.SizeOf(typeof(LimitSample)) == 96 && Marshal.SizeOf(typeof(Pick)) == 184, "LimitSample/Pick size");
        Check(Marshal.OffsetOf(typeof(Pick), "t").ToInt32() == 152 && Marshal.OffsetOf(typeof(Pick), "iterations").ToInt32() == 176, "Pick offsets");
        Check(Marshal.SizeOf(typeof(GrabOptions)) == 8 && Marshal.SizeOf(typeof(FloorOptions)) == 16, "option sizes");
        Check(Marshal.SizeOf(typeof(RemoteOptions)) == 16 + IntPtr.Size && Marshal.OffsetOf(typeof(RemoteOptions), "auth_token").ToInt32() == 16 &&
              Marshal.SizeOf(typeof(GeometryStatus)) == 24, "RemoteOptions/GeometryStatus size");
        Check(Marshal.SizeOf(typeof(EmbeddedOptions)) == 88 + IntPtr.Size && Marshal.OffsetOf(typeof(EmbeddedOptions), "http_host").ToInt32() == 16 &&
              Marshal.OffsetOf(typeof(EmbeddedOptions), "keep_results").ToInt32() == 80 &&
              Marshal.OffsetOf(typeof(EmbeddedOptions), "data_dir").ToInt32() == 88,
              "EmbeddedOptions layout");

        Check(Native.ss_abi_version() == Native.AbiVersion, "ABI version " + Native.ss_abi_version());
        string version = Native.Utf8(Native.ss_version());
        uint number = Native.ss_version_number();
        Check(version == string.Format("{0}.{1}.{2}", number >> 16, (number >> 8) & 255, number & 255), "version " + version);
        Check(Native.Utf8(Native.ss_status_name(Status.NotReady)) == "not_ready", "status name");
        Native.Check(Native.ss_set_log_callback(logCallback, IntPtr.Zero, LogLevel.Info));

        Material aluminium;
        Native.Check(Native.ss_material_preset(Native.Utf8("aluminium"), 0.01, out aluminium));
        Check(aluminium.youngs_modulus == 6.9e10 && aluminium.thickness == 0.01, "aluminium preset");
        Material none;
        Check(Native.ss_material_preset(Native.Utf8("cheese"), 0.01, out none) == Status.InvalidArgument &&
              Native.LastError().Contains("known:"), "unknown preset is refused with the known names");

        EmbeddedOptions options;
        Native.ss_embedded_options_default(out options);
        options.listen = 1;
        options.SetHttpHost("127.0.0.1");
        IntPtr session;
        Native.Check(Native.ss_session_create_embedded(ref options, out session));
        int port;
        Native.Check(Native.ss_session_embedded_port(session, out port));
        Check(port > 0, "the listener has a port");

        IntPtr plate = Plate();
        GeomId id;
        int created;
        Native.Check(Native.ss_session_upload(session, plate, ref aluminium, null, out id, out created));
        Check(created == 1, "new geometry");
        var hex = new byte[33];
        Native.Check(Native.ss_geom_id_to_hex(ref id, hex, hex.Length));

        // A loading bar: poll the precomputation.
        GeometryStatus status;
        var why = new byte[256];
        double last = 0;
        bool monotone = true;
        for (int frame = 0; frame < 100000; ++frame)
        {
            Native.Check(Native.ss_session_geometry_status(session, ref id, out status, why, why.Length));
            monotone &= status.progress >= last && status.progress <= 1.0;
            last = status.progress;
            if (status.status != GeometryState.Precomputing) break;
            Thread.Sleep(1);
        }
        Native.Check(Native.ss_session_geometry_status(session, ref id, out status, why, why.Length));
        Check(status.status == GeometryState.Ready && status.progress == 1.0 && monotone, "precomputation finished");
        Check(status.num_vertices == NV && status.num_faces == N * N, "geometry counts");
        Check(Interlocked.CompareExchange(ref precomputeLogs, 0, 0) == 1, "the server's log reached the C# callback");

        // Deform twice, asynchronously: F and 2F.
        IntPtr one = Cantilever(1.0), two = Cantilever(2.0);
        int frames1, frames2;
        double[] u1 = DeformAsync(session, id, one, out frames1);
        double[] u2 = DeformAsync(session, id, two, out frames2);
        double[] rest = new double[3 * NV];
        int count;
        Native.Check(Native.ss_mesh_positions(plate, rest, NV, out count));
        double clampMotion = 0, worstLinearity = 0, worstSymmetry = 0, tip = 0;
        for (int j = 0; j <= N; ++j)
            for (int i = 0; i <= N; ++i)
            {
                int k = j * (N + 1) + i, mirror = (N - j) * (N + 1) + i;
                for (int a = 0; a < 3; ++a)
                {
                    double d1 = u1[3 * k + a] - rest[3 * k + a], d2 = u2[3 * k + a] - rest[3 * k + a];
                    if (i < 2) clampMotion = Math.Max(clampMotion, Math.Abs(d1));
                    worstLinearity = Math.Max(worstLinearity, Math.Abs(d2 - 2 * d1));
                }
                double z = u1[3 * k + 2] - rest[3 * k + 2], zm = u1[3 * mirror + 2] - rest[3 * mirror + 2];
                worstSymmetry = Math.Max(worstSymmetry, Math.Abs(z - zm));
                tip = Math.Min(tip, z);
            }
        Console.WriteLine(string.Format("csharp: softshell {0} via {1}, plate {2} control points, tip deflection {3:E3} m " +
                                        "(polled {4} + {5} frames)", version, Native.Lib, NV, tip, frames1, frames2));
        Check(clampMotion == 0.0, "the clamped control points stay put");
        Check(tip < -1e-9, "the free edge goes down");
        Check(worstLinearity <= 1e-9 * Math.Abs(tip), "twice the force, twice the displacement");
        Check(worstSymmetry <= 1e-9 * Math.Abs(tip), "a symmetric load gives a symmetric shape");

        // Stresses at the level-1 tessellation's vertices: twice the force, twice every stress.
        StressSample[] s1 = Stresses(session, id, 1), s2 = Stresses(session, id, 2);
        double worstStress = 0, largestStress = 0;
        for (int k = 0; k < s1.Length; ++k)
        {
            largestStress = Math.Max(largestStress, s1[k].von_mises_top);
            worstStress = Math.Max(worstStress, Math.Abs(s2[k].von_mises_top - 2 * s1[k].von_mises_top));
        }
        Check(s1.Length == (2 * N + 1) * (2 * N + 1) && s2.Length == s1.Length, "one stress sample per level-1 vertex");
        Check(largestStress > 0 && worstStress <= 1e-9 * largestStress, "twice the force, twice the stress");
        IntPtr noField;
        Check(Native.ss_session_stresses(session, ref id, 99, 1, null, 0, 0.0, out noField) == Status.NotFound &&
              noField == IntPtr.Zero, "stresses of an unknown result: not found");

        // Through the listener, as a second device: a remote session on the same server.
        RemoteOptions remoteOptions;
        Native.ss_remote_options_default(out remoteOptions);
        IntPtr remote;
        Native.Check(Native.ss_session_create_remote(Native.Utf8("http://127.0.0.1:" + port), ref remoteOptions, out remote));
        int hasNew;
        uint resId;
        var latest = new double[3 * NV];
        Native.Check(Native.ss_session_latest_result(remote, ref id, 0, 0, out hasNew, out resId, latest, NV, out count));
        Check(hasNew == 1 && resId == 2 && Math.Abs(latest[3 * N + 2] - u2[3 * N + 2]) < 1e-12, "the remote client sees the result");

        // Holds and events: the remote client follows while the embedded one holds the plate as a
        // cantilever (the same request as a hold: the same shape), then lets go (the rest shape).
        IntPtr feed;
        Native.Check(Native.ss_session_subscribe(remote, ref id, 2, out feed));
        IntPtr put;
        Native.Check(Native.ss_session_put_hold_begin(session, ref id, Native.Utf8("csharp.clamp"), one, 10000, out put));
        int putReady = 0, putFrames = 0;
        while (putReady == 0 && putFrames < 100000)
        {
            Native.Check(Native.ss_hold_put_poll(put, out putReady));
            if (putReady == 0) { ++putFrames; Thread.Sleep(1); }
        }
        uint heldId;
        ulong holdVersion;
        var held = new double[3 * NV];
        Native.Check(Native.ss_hold_put_read(put, out heldId, out holdVersion, held, NV, out count));
        Native.ss_hold_put_destroy(put);
        double worstHeld = 0;
        for (int k = 0; k < 3 * NV; ++k) worstHeld = Math.Max(worstHeld, Math.Abs(held[k] - u1[k]));
        Check(heldId == 3 && holdVersion == 1 && worstHeld <= 1e-9 * Math.Abs(tip), "the hold's result is the cantilever");
        int followed = 0;
        uint seen = 0;
        for (int frame = 0; frame < 10000 && seen < 3; ++frame)
        {
            Native.Check(Native.ss_subscription_poll(feed, out followed, out seen, latest, NV, out count));
            if (seen < 3) Thread.Sleep(1);
        }
        int feedState;
        Native.Check(Native.ss_subscription_state(feed, out feedState));
        Check(seen == 3 && feedState == Native.FeedLive && Math.Abs(latest[3 * N + 2] - held[3 * N + 2]) < 1e-12,
              "the follower got the hold's result through the event stream");
        uint releasedId;
        Native.Check(Native.ss_session_release_hold(session, ref id, Native.Utf8("csharp.clamp"), out releasedId));
        Check(releasedId == 4, "releasing stores the rest shape");
        Check(Native.ss_session_release_hold(session, ref id, Native.Utf8("csharp.clamp"), out releasedId) == Status.NotFound,
              "a released hold is gone");
        // Deleting the geometry: the follower's stream ends, the id is unknown, and the same content
        // uploaded again continues the result ids (1..4 belonged to the deleted upload).
        Native.Check(Native.ss_session_remove_geometry(session, ref id));
        Check(Native.ss_session_geometry_status(remote, ref id, out status, why, why.Length) == Status.NotFound,
              "a deleted geometry is unknown");
        Check(Native.ss_session_remove_geometry(remote, ref id) == Status.NotFound && Native.LastError().Contains("no geometry with id"),
              "deleting it again: not found");
        for (int frame = 0; frame < 10000 && feedState != Native.FeedFailed; ++frame)
        {
            Native.Check(Native.ss_subscription_state(feed, out feedState));
            if (feedState != Native.FeedFailed) Thread.Sleep(1);
        }
        // What arrived before the end is taken first (the release's result 4), then the end: Gone.
        Status polled = Status.Ok;
        for (int taken = 0; taken < 10 && polled == Status.Ok; ++taken)
            polled = Native.ss_subscription_poll(feed, out followed, out seen, latest, NV, out count);
        Check(feedState == Native.FeedFailed && polled == Status.Gone, "the follower's stream ends with gone");
        GeomId again;
        Native.Check(Native.ss_session_upload(remote, plate, ref aluminium, null, out again, out created));
        Check(created == 1 && again.Equals(id), "uploaded again: a new geometry under the same id");
        Native.Check(Native.ss_session_deform(remote, ref again, one, out resId, latest, NV, out count));
        Check(resId == 5, "the ids continue after the deleted upload's (got " + resId + ")");
        Native.ss_subscription_destroy(feed);
        Native.ss_session_destroy(remote);

        // Handles are generation-checked: a destroyed one is an error, not a crash.
        Native.ss_request_destroy(one);
        int a0, a1, a2, a3, a4;
        Check(Native.ss_request_counts(one, out a0, out a1, out a2, out a3, out a4) == Status.InvalidArgument &&
              Native.LastError().Contains("destroyed"), "stale handle detected");
        try
        {
            Native.Check(Native.ss_request_counts(IntPtr.Zero, out a0, out a1, out a2, out a3, out a4));
            Check(false, "Check throws");
        }
        catch (SoftshellException e)
        {
            Check(e.Status == Status.InvalidArgument && e.Message.Contains("NULL"), "SoftshellException carries status and message");
        }

        Native.ss_request_destroy(two);
        Native.ss_mesh_destroy(plate);
        Native.ss_session_destroy(session);
        Native.Check(Native.ss_set_log_callback(null, IntPtr.Zero, LogLevel.Off));
        Console.WriteLine(string.Format("csharp: {0} checks, {1} failures", checks, failures));
        return failures == 0 ? 0 : 1;
    }
}
