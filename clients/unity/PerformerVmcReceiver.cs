// Drives a Humanoid avatar from live-performer's VMC stream (OSC over UDP, port 39539).
//
// Setup: put OscParser.cs and this file under Assets/, add this component to the
// avatar (the GameObject with the Animator whose Avatar is Humanoid), stand the model
// in a T-pose in the scene, press Play, then run `performer run` (docs/receivers.md).
//
// The stream gives, per bone, its local rotation relative to the T-pose in Unity's
// frame (left-handed, Y up, the character faces +Z) with the axes of the avatar's root,
// as for a VRM "normalized" rig. A model's own bones have arbitrary rest axes, so each
// rotation q is applied between the rest orientations captured at Start:
//     localRotation = inverse(restRootRel(parent transform)) * q * restRootRel(bone)
// which leaves the model in its rest pose when q is identity (and is just q on a
// normalized VRM). Bones the model lacks (e.g. Chest, Toes) are skipped.
//
// Where the performer stands and faces (issue 39): /VMC/Ext/Root/Pos is the model root,
// with `performer run --vmc-root world` (the default) its place on the stage and its heading.
// Root Motion World moves and turns this avatar's transform by it (scaled to the avatar, from
// where the avatar stood at Start); In Place ignores it: the avatar dances on its spot.
// VmcFrame.cs collects each frame (plain C#, checked outside Unity by Tests/OscParserCheck.cs).
using System;
using System.Collections.Generic;
using System.Net;
using System.Net.Sockets;
using System.Threading;
using UnityEngine;

namespace LivePerformer
{
    [AddComponentMenu("Live Performer/Performer Vmc Receiver")]
    public class PerformerVmcReceiver : MonoBehaviour
    {
        [Tooltip("UDP port the engine sends VMC to (performer run --osc HOST:PORT; default 39539)")]
        public int port = 39539;
        [Tooltip("The Humanoid Animator to drive; default: the one on this GameObject")]
        public Animator animator;
        [Tooltip("Move the Hips with the stream's root position (scaled to this avatar's hip height)")]
        public bool applyRootPosition = true;
        [Tooltip("Hip height of the stream's rig in metres (models/assets/humanoid_rest.json, hello rest_offsets[0])")]
        public float streamHipsHeight = 0.9256f;
        public enum RootMotion { World, InPlace }
        [Tooltip("World: move and turn the avatar by /VMC/Ext/Root/Pos (the performer's place on the stage and "
                 + "heading, performer run --vmc-root world); In Place: ignore it")]
        public RootMotion rootMotion = RootMotion.World;

        class Target { public Transform bone; public Quaternion pre, post; }

        readonly Dictionary<string, Target> targets = new Dictionary<string, Target>();
        readonly object gate = new object();
        readonly VmcFrameAssembler assembler = new VmcFrameAssembler();
        VmcFrame latest;
        Vector3 startPosition;
        Quaternion startRotation;
        Vector3 restHips;
        float hipsScale = 1f;
        UdpClient udp;
        Thread thread;
        volatile bool running;

        public int FramesReceived { get; private set; }
        public int MalformedDatagrams { get; private set; }

        void Start()
        {
            if (animator == null) animator = GetComponent<Animator>();
            if (animator == null || !animator.isHuman)
            {
                Debug.LogError("PerformerVmcReceiver needs a Humanoid Animator (Rig > Animation Type: Humanoid)");
                enabled = false;
                return;
            }
            Quaternion rootInv = Quaternion.Inverse(animator.transform.rotation);
            foreach (HumanBodyBones b in Enum.GetValues(typeof(HumanBodyBones)))
            {
                if (b == HumanBodyBones.LastBone) continue;
                Transform t = animator.GetBoneTransform(b);
                if (t == null) continue;
                targets[b.ToString()] = new Target
                {
                    bone = t,
                    pre = Quaternion.Inverse(rootInv * t.parent.rotation), // rest, relative to the avatar root
                    post = rootInv * t.rotation,
                };
            }
            Transform hips = animator.GetBoneTransform(HumanBodyBones.Hips);
            restHips = hips.localPosition;
            startPosition = animator.transform.position;
            startRotation = animator.transform.rotation;
            hipsScale = animator.transform.InverseTransformPoint(hips.position).y / streamHipsHeight;
            try
            {
                udp = new UdpClient(new IPEndPoint(IPAddress.Any, port));
            }
            catch (SocketException e)
            {
                Debug.LogError($"PerformerVmcReceiver: cannot listen on UDP port {port}: {e.Message} (EVMC4U or another receiver already there?)");
                enabled = false;
                return;
            }
            running = true;
            thread = new Thread(Receive) { IsBackground = true, Name = "VMC receiver" };
            thread.Start();
        }

        // Background thread: parse datagrams; a frame is complete at /VMC/Ext/T.
        void Receive()
        {
            var from = new IPEndPoint(IPAddress.Any, 0);
            var messages = new List<OscMessage>();
            while (running)
            {
                byte[] data;
                try { data = udp.Receive(ref from); }
                catch (SocketException) { continue; }
                catch (ObjectDisposedException) { return; }
                messages.Clear();
                if (!OscParser.TryParse(data, data.Length, messages)) { MalformedDatagrams++; continue; }
                foreach (OscMessage m in messages)
                {
                    VmcFrame done = assembler.Feed(m);
                    if (done != null)
                    {
                        lock (gate)
                        {
                            latest = done;
                            FramesReceived++;
                        }
                    }
                }
            }
        }

        void LateUpdate() // after the Animator, so the stream wins over any animation
        {
            VmcFrame frame;
            lock (gate) { frame = latest; }
            if (frame == null) return;
            foreach (var kv in frame.Bones)
            {
                float[] v = kv.Value;
                if (targets.TryGetValue(kv.Key, out Target t))
                    t.bone.localRotation = t.pre * new Quaternion(v[3], v[4], v[5], v[6]) * t.post;
            }
            if (rootMotion == RootMotion.World)
            {
                // the performer's place on the stage (scaled to this avatar) and heading, from where it stood at Start
                float[] p = frame.RootPosition, r = frame.RootRotation;
                animator.transform.SetPositionAndRotation(
                    startPosition + startRotation * (new Vector3(p[0], p[1], p[2]) * hipsScale),
                    startRotation * new Quaternion(r[0], r[1], r[2], r[3]));
            }
            Vector3 hips = frame.Bones.TryGetValue("Hips", out float[] hv) ? new Vector3(hv[0], hv[1], hv[2])
                                                                            : new Vector3(0f, streamHipsHeight, 0f);
            if (applyRootPosition && targets.TryGetValue("Hips", out Target h))
            {
                // The stream's hips position is relative to its floor origin; move ours by the same
                // displacement from the rest height, scaled to this avatar, in the root's axes.
                Vector3 delta = (hips - new Vector3(0f, streamHipsHeight, 0f)) * hipsScale;
                Transform parent = h.bone.parent;
                Vector3 restWorld = parent.TransformPoint(restHips);
                h.bone.position = restWorld + animator.transform.TransformVector(delta);
            }
        }

        void OnDestroy()
        {
            running = false;
            udp?.Close();
            thread?.Join(500);
        }
    }
}
