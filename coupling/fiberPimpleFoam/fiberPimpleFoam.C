/*---------------------------------------------------------------------------*\
    fiberform - simulator of early paper forming
    SPDX-License-Identifier: GPL-3.0-or-later
-------------------------------------------------------------------------------
Application
    fiberPimpleFoam

Description
    Transient incompressible solver (PIMPLE) for the suspending fluid of a
    fiber suspension: pimpleFoam on a static mesh plus one explicit momentum
    source, the field fiberSource, which carries the forces of the fibers on
    the fluid in two-way coupling.

        ddt(U) + div(phi U) - div(R) = -grad(p) + fiberSource + fvOptions(U)
        div(U) = 0

    Kinematic units as in every incompressible OpenFOAM solver:
        U           velocity                                [m/s]
        p           pressure / rho                          [m2/s2]
        fiberSource force per unit volume / rho             [m/s2]

    0/fiberSource is optional: when absent the source is zero and the solver
    reproduces pimpleFoam exactly. See docs/coupling/fiberPimpleFoam.md.

    -coupled: two-way coupling with fiberdem (fix fiber/coupling) under one
    mpirun (coupling/layer): one step of interval x fiber step per exchange,
    fiberSource = fiberSource0 + reaction / (rho V); see coupledRun.H and
    docs/coupling/launch.md. -coupled -parallel: the fluid on several ranks,
    with OpenFOAM's libPstream rebuilt with the MPMD split
    (scripts/setup/openfoam-pstream.sh, through LD_LIBRARY_PATH).

Restrictions
    Static mesh (no dynamicMeshDict motion), no MRF zones. -coupled: a uniform
    axis-aligned blockMesh box or constant/fiberExchangeMap.

\*---------------------------------------------------------------------------*/

#include "fvCFD.H"
#include "singlePhaseTransportModel.H"
#include "turbulentTransportModel.H"
#include "pimpleControl.H"
#include "fvOptions.H"

#include "coupledCells.H"
#include "coupling_layer.h"
#include "exchange_map.h"

#include <dlfcn.h>

#include <cstring>
#include <memory>

// The communicator of this program's ranks exported by the rebuilt libPstream
// (scripts/setup/openfoam-pstream.sh); nullptr with Debian's stock library.
static MPI_Comm* fiberformPstreamWorld()
{
    return static_cast<MPI_Comm*>(dlsym(RTLD_DEFAULT, "fiberform_pstream_world"));
}

// * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * //

int main(int argc, char *argv[])
{
    argList::addNote
    (
        "Transient incompressible PIMPLE solver with a fiber momentum source"
        " (fiberSource, m/s^2) for fiber-fluid coupling."
    );

    argList::addBoolOption
    (
        "coupled",
        "two-way coupling with fiberdem under one mpirun (MPMD; with -parallel"
        " the rebuilt libPstream is needed): fiberSource gets the fibers'"
        " reaction every exchange; see docs/coupling/launch.md"
    );
    argList::addOption
    (
        "couplingTimeout",
        "s",
        "deadline of each blocking coupling exchange in s (default 300)"
    );

    // Coupled mode, serial fluid: this solver starts MPI itself, before OpenFOAM parses the
    // arguments, and splits MPI_COMM_WORLD by MPI_APPNUM (coupling/layer start_world). Serial
    // OpenFOAM never touches MPI, so Debian's stock libraries work.
    // Coupled mode, parallel fluid (-parallel): OpenFOAM starts MPI, and the rebuilt libPstream
    // (scripts/setup/openfoam-pstream.sh) splits MPI_COMM_WORLD by MPI_APPNUM in UPstream::init;
    // the coupling layer connects over that same split (join_world below), never splitting again.
    // Debian's stock libPstream would take the fibers' ranks for fluid ranks and hang: refused here.
    bool coupled = false, parallel = false;
    for (int i = 1; i < argc; ++i)
    {
        coupled = coupled || std::strcmp(argv[i], "-coupled") == 0;
        parallel = parallel || std::strcmp(argv[i], "-parallel") == 0;
    }
    if (coupled)
    {
        if (parallel && !fiberformPstreamWorld())
        {
            std::fprintf
            (
                stderr,
                "fiberPimpleFoam: -coupled -parallel needs OpenFOAM's libPstream rebuilt with the"
                " MPMD split (scripts/setup/openfoam-pstream.sh, part of make setup): start with"
                " LD_LIBRARY_PATH=<its directory, default .deps/openfoam-pstream>"
                " (docs/coupling/launch.md)\n"
            );
            return 2;
        }
        if (!parallel)
        {
            MPI_Init(&argc, &argv);
            fiberform::coupling::start_world();
        }
    }

    #include "postProcess.H"

    #include "addCheckCaseOptions.H"
    #include "setRootCaseLists.H"

    if (coupled && parallel)
    {
        // UPstream::init has split MPI_COMM_WORLD (rebuilt libPstream): connect over that split
        fiberform::coupling::join_world(*fiberformPstreamWorld());
    }
    #include "createTime.H"
    #include "createMesh.H"
    #include "createControl.H"
    #include "createTimeControls.H"
    #include "initContinuityErrs.H"
    #include "createFields.H"
    #include "CourantNo.H"
    #include "setInitialDeltaT.H"

    turbulence->validate();

    if (coupled)
    {
        #include "coupledRun.H"
    }
    else
    {
        Info<< "\nStarting time loop\n" << endl;

        while (runTime.run())
        {
            #include "readTimeControls.H"
            #include "CourantNo.H"
            #include "setDeltaT.H"

            ++runTime;

            Info<< "Time = " << runTime.timeName() << nl << endl;

            #include "pimpleStep.H"

            runTime.write();

            runTime.printExecutionTime(Info);
        }
    }

    Info<< "End\n" << endl;

    if (coupled && !parallel)
    {
        MPI_Finalize();  // parallel: OpenFOAM finalizes MPI when args goes out of scope
    }

    return 0;
}


// ************************************************************************* //
