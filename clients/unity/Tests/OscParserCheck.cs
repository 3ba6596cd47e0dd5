// Checks OscParser outside Unity on datagrams written by the engine's VMC encoder.
//
//   mcs -out:check.exe ../OscParser.cs ../VmcFrame.cs OscParserCheck.cs && mono check.exe frame0.bin frame1.bin
//   (or: dotnet new console, add the three files, dotnet run -- frame0.bin frame1.bin)
//
// Prints one line per message: address, then its arguments (floats with 6 decimals);
// "MALFORMED <file>" for a datagram that does not parse; at each /VMC/Ext/T the frame
// VmcFrameAssembler completed: "FRAME time root x y z rotation x y z w hips-world x y z"
// (what PerformerVmcReceiver applies). tests/test_listen.py writes
// the datagrams and compares the output with python-osc's reading when mcs or dotnet
// is installed.
using System;
using System.Collections.Generic;
using System.Globalization;
using System.IO;
using System.Linq;
using LivePerformer;

public static class OscParserCheck
{
    public static int Main(string[] files)
    {
        var messages = new List<OscMessage>();
        var assembler = new VmcFrameAssembler();
        foreach (string file in files)
        {
            byte[] data = File.ReadAllBytes(file);
            messages.Clear();
            if (!OscParser.TryParse(data, data.Length, messages))
            {
                Console.WriteLine("MALFORMED " + Path.GetFileName(file));
                continue;
            }
            foreach (OscMessage m in messages)
            {
                var args = m.Args.Select(a => a is float f ? f.ToString("F6", CultureInfo.InvariantCulture) : Convert.ToString(a, CultureInfo.InvariantCulture));
                Console.WriteLine(m.Address + " " + string.Join(" ", args));
                VmcFrame frame = assembler.Feed(m);
                if (frame != null)
                {
                    var nums = new[] { frame.Time }.Concat(frame.RootPosition).Concat(frame.RootRotation)
                        .Concat(frame.HipsWorldPosition());
                    Console.WriteLine("FRAME " + string.Join(" ", nums.Select(f => f.ToString("F6", CultureInfo.InvariantCulture))));
                }
            }
        }
        return 0;
    }
}
