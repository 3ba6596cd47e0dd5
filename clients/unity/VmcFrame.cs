// One VMC frame as PerformerVmcReceiver applies it, and the assembler that collects it from OSC
// messages. Plain C#, no UnityEngine: check it outside Unity with Tests/OscParserCheck.cs.
//
// All values are in Unity's frame (left-handed, Y up, the character faces +Z), metres.
// /VMC/Ext/Root/Pos is the model root: with `performer run --vmc-root world` (the default)
// where the performer stands on the stage (x, 0, z) and its heading (a rotation about +Y);
// with in-place or hips the identity at the origin. The Hips' local position and rotation
// are relative to that root, so HipsWorldPosition() = root + rootRotation * hips.
using System.Collections.Generic;

namespace LivePerformer
{
    public sealed class VmcFrame
    {
        public float[] RootPosition = { 0f, 0f, 0f };
        public float[] RootRotation = { 0f, 0f, 0f, 1f }; // x, y, z, w
        /// <summary>Bone name -> local position x, y, z and rotation x, y, z, w.</summary>
        public readonly Dictionary<string, float[]> Bones = new Dictionary<string, float[]>();
        public float Time;

        /// <summary>The Hips' position in the root's parent frame: root + rootRotation * hips (metres).</summary>
        public float[] HipsWorldPosition()
        {
            float[] h = Bones.TryGetValue("Hips", out float[] v) ? v : new float[7];
            float[] q = RootRotation;
            // v' = v + 2w (u x v) + 2 u x (u x v), u = (q.x, q.y, q.z)
            float tx = 2f * (q[1] * h[2] - q[2] * h[1]);
            float ty = 2f * (q[2] * h[0] - q[0] * h[2]);
            float tz = 2f * (q[0] * h[1] - q[1] * h[0]);
            return new[]
            {
                RootPosition[0] + h[0] + q[3] * tx + (q[1] * tz - q[2] * ty),
                RootPosition[1] + h[1] + q[3] * ty + (q[2] * tx - q[0] * tz),
                RootPosition[2] + h[2] + q[3] * tz + (q[0] * ty - q[1] * tx),
            };
        }
    }

    /// <summary>Collects /VMC/Ext/Root/Pos, /VMC/Ext/Bone/Pos ... /VMC/Ext/T into frames.</summary>
    public sealed class VmcFrameAssembler
    {
        VmcFrame pending = new VmcFrame();

        /// <summary>Feed one message; returns the frame it completes (at /VMC/Ext/T), else null.</summary>
        public VmcFrame Feed(OscMessage m)
        {
            if (m.Address == "/VMC/Ext/Root/Pos" && Floats(m, 7, out float[] r))
            {
                pending.RootPosition = new[] { r[0], r[1], r[2] };
                pending.RootRotation = new[] { r[3], r[4], r[5], r[6] };
            }
            else if (m.Address == "/VMC/Ext/Bone/Pos" && m.Args.Length >= 8 && m.Args[0] is string name
                     && Floats(m, 7, out float[] b))
            {
                pending.Bones[name] = b;
            }
            else if (m.Address == "/VMC/Ext/T" && m.Args.Length >= 1 && m.Args[0] is float t)
            {
                VmcFrame done = pending;
                done.Time = t;
                pending = new VmcFrame();
                return done;
            }
            return null;
        }

        // The 7 floats after the name (VMC v2.1 adds scale and offset after them: ignored).
        static bool Floats(OscMessage m, int n, out float[] values)
        {
            values = new float[n];
            if (m.Args == null || m.Args.Length < n + 1) return false;
            for (int k = 0; k < n; k++)
            {
                if (!(m.Args[k + 1] is float f)) return false;
                values[k] = f;
            }
            return true;
        }
    }
}
